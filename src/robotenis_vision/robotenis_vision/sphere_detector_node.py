"""
The `sphere_detector` node: the sphere's centre from the hand camera's images.

Subscribes camera/image_raw (sensor_msgs/Image, mono8, read from its bytes: robotenis_ros.cdr)
and camera/camera_info (sensor-data QoS);
publishes sphere/position (geometry_msgs/PointStamped, optical frame, m, stamp of the image) and
sphere/detection (robotenis_interfaces/SphereDetection: covariance, frames, edge points, fit RMS,
method). With ``frames`` > 1 it publishes the average of every ``frames`` detections (outliers
rejected, robotenis_vision.averaging), stamped with the last image. A frame it cannot trust is
dropped with the reason, published on sphere/dropped (std_msgs/String: a calibration session
says why a pose had no detections) and in a rate-limited log line (two balls in view among them:
ambiguous).

Two methods (robotenis_vision.rest): ``method`` (default 'conic', seeded by the last frame: about
1.5 ms a frame; a search of the whole image when the seed is lost, and while the ball stays lost
once every ``search_interval`` of image time) on every frame, and once the
ball has stood still in the image (its outline moved less than ``rest_motion_px`` for
``rest_frames`` frames: the robot at rest) ``rest_method`` (default 'model', the accurate fit,
about 15-40 ms a fit) runs on the mean image of the frames at rest on the first and when their
number reaches 8, 16, 32, ... (robotenis_vision.rest), and every frame's fast detection is
published corrected by it (method 'conic+model mean'), or dropped while it has no correction (the
accurate fit refused that ball); while the ball moves the fast one is (figures: ``./robotenis
bench vision``). The fit at rest models the background behind the ball from a plate of the
rests before (``background_plate``, robotenis_vision.plate). Parameters: the table PARAMETERS.
"""
import sys

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from robotenis_interfaces.msg import SphereDetection
from robotenis_kinematics import description
from robotenis_ros import cdr
from robotenis_ros.convert import point_stamped, stamp_seconds
from robotenis_ros.node import declare_parameters, spin
from robotenis_vision import averaging, camera as camera_model, detector, plate
from robotenis_vision.rest import MOTION_PX, outline_px, RestCorrection, STILL_FRAMES
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header, String

PARAMETERS = {
    'method': ('conic', f"on every frame: one of {', '.join(detector.METHODS)}"),
    'rest_method': ('model', 'once the ball stands still in the image: corrects the detection '
                             "from the frames' mean image (one of the methods, or '' for never)"),
    'rest_motion_px': (MOTION_PX, 'px: the ball stands still when its outline (centre and '
                                  'radius) moves less between frames'),
    'rest_frames': (STILL_FRAMES, 'frames it must stand still for rest_method'),
    'rest_every_frame': (False, 'rest_method on every frame at rest instead of on mean images '
                                '(10x the CPU; its bias differs on scenes it misfits: bench '
                                'vision)'),
    'background_plate': (True, 'the fit at rest takes the background behind the ball from the '
                               'rests before, where the ball was elsewhere (a camera that only '
                               'translates, a background far behind the ball: '
                               'robotenis_vision.plate; where the views disagree it is not used)'),
    'gamma': (1.0, "the camera's response, grey = 255 (I / 255)^(1 / gamma) (1: linear)"),
    'radius': (0.0, 'm: the sphere radius (0: from the robot description)'),
    'description_path': (description.config_path('nominal.yaml'), 'the robot description YAML'),
    'frames': (1, 'detections averaged per published measurement'),
    'max_fit_rms_px': (0.5, 'px: an outline fit worse than this (RMS) makes the frame untrusted'),
    'use_prior': (True, "the previous frame's detection seeds the next one (about half the time "
                        'at rest), moved at the velocity of the two last ones; the whole image '
                        'is searched when it does not fit'),
    'image_queue': (qos_profile_sensor_data.depth, 'frames kept for the node while it is busy '
                                                   '(sensor-data QoS of this depth; older ones '
                                                   'are dropped)'),
    'search_interval': (0.2, 's of image time: once the ball is lost, the whole image is searched '
                             'again after this long, the frames between left unmeasured (a '
                             'search that finds nothing took 85-120 ms here in a live session: on '
                             'every frame it held a core while the ball was out of view)'),
}


def detection_message(det, header, frames):
    out = SphereDetection()
    out.header = header
    out.position.x, out.position.y, out.position.z = (float(v) for v in det.position)
    out.covariance = [float(v) for v in np.asarray(det.covariance).ravel()]
    out.frames = int(frames)
    out.edge_points = int(len(det.edge_points))
    out.fit_rms_px = float(det.fit_rms_px) if np.isfinite(det.fit_rms_px) else 0.0
    out.method = det.method
    return out


class SphereDetectorNode(Node):
    def __init__(self):
        super().__init__('sphere_detector')
        p = declare_parameters(self, PARAMETERS)
        self.method, self.rest_method = p['method'], p['rest_method']
        if self.method not in detector.METHODS:
            raise ValueError(f"method must be one of {', '.join(detector.METHODS)}, "
                             f'got {self.method!r}')
        if self.rest_method not in detector.METHODS + ('',):
            raise ValueError(f"rest_method must be one of {', '.join(detector.METHODS)} or '', "
                             f'got {self.rest_method!r}')
        self.gamma = float(p['gamma'])
        if not self.gamma > 0:
            raise ValueError(f'gamma must be positive, got {self.gamma}')
        self.radius = float(p['radius']) or description.load(p['description_path']).sphere_radius
        self.rest = None                # the fast method corrected at rest (rest_method)
        self.plate = None               # the background behind the ball (background_plate)
        if self.rest_method and self.rest_method != self.method:
            self.rest = RestCorrection(float(p['rest_motion_px']), int(p['rest_frames']),
                                       self.rest_fit, self.rest_method,
                                       bool(p['rest_every_frame']),
                                       self.rest_seen if p['background_plate'] else None)
        self.frames = max(1, int(p['frames']))
        self.max_rms = float(p['max_fit_rms_px'])
        self.use_prior = bool(p['use_prior'])
        self.track = ()                 # (image time, Detection) of the last one or two frames
        self.search_interval = float(p['search_interval'])
        if not self.search_interval >= 0:
            raise ValueError(f'search_interval must not be negative, got {self.search_interval}')
        self.next_search = -np.inf      # image time (s) before which a lost ball is not searched
        self.camera = None
        self.camera_key = None
        self.batch = []
        self.position_pub = self.create_publisher(PointStamped, 'sphere/position', 10)
        self.detection_pub = self.create_publisher(SphereDetection, 'sphere/detection', 10)
        self.dropped_pub = self.create_publisher(String, 'sphere/dropped', 10)
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_camera_info,
                                 qos_profile_sensor_data)
        images = QoSProfile(history=qos_profile_sensor_data.history,
                            depth=max(1, int(p['image_queue'])),
                            reliability=qos_profile_sensor_data.reliability,
                            durability=qos_profile_sensor_data.durability)
        self.create_subscription(Image, 'camera/image_raw', self.on_image, images, raw=True)
        self.get_logger().info(f'sphere radius {self.radius * 1e3:.2f} mm, method {self.method}'
                               f"{', at rest ' + self.rest_method if self.rest_method else ''}, "
                               f'{self.frames} frame(s) per measurement')

    def drop(self, reason):
        """Publish why a frame gave no measurement (sphere/dropped), and log it (rate-limited)."""
        self.dropped_pub.publish(String(data=reason))
        self.get_logger().warn(f'frame dropped: {reason}', throttle_duration_sec=2.0)

    def on_camera_info(self, msg):
        key = (tuple(msg.k), tuple(msg.d), msg.width, msg.height, msg.distortion_model)
        if key == self.camera_key:
            return
        try:
            self.camera = camera_model.from_camera_info(msg)
            self.camera_key = key
            self.plate = None           # another camera sees another background
        except camera_model.CameraError as e:
            self.get_logger().error(f'camera_info unusable: {e}', throttle_duration_sec=5.0)

    def on_image(self, data):
        if self.camera is None:
            self.drop('no camera_info received yet')
            return
        try:
            frame = cdr.image(data)
        except ValueError as e:
            self.drop(str(e))
            return
        header = Header(stamp=Time(sec=frame.sec, nanosec=frame.nanosec),
                        frame_id=frame.frame_id or 'camera_optical')
        t = stamp_seconds(header.stamp)
        track, self.track = self.track, ()
        if not track and self.next_search - self.search_interval <= t < self.next_search:
            return                      # the ball was lost (the reason logged)
        seed = detector.moved_prior(self.camera, track, t) if track else None
        image = frame.pixels
        try:
            det = detector.detect(image, self.camera, self.radius, self.method, seed,
                                  self.gamma)
        except (ValueError, detector.DetectionError) as e:
            self.drop(str(e))
            if self.rest:
                self.rest.lost()
            self.next_search = t + self.search_interval
            return
        if self.use_prior and det.method != 'baseline':
            self.track = track[-1:] + ((t, det),)
        if self.rest:
            det, failure = self.rest.update(
                image, det, outline_px(self.camera, det.position, self.radius))
            if det is None:
                self.drop(f'{self.rest_method} {failure}')
                return
            if failure:
                self.get_logger().info(f'{self.rest_method} {failure}', throttle_duration_sec=5.0)
        if np.isfinite(det.fit_rms_px) and det.fit_rms_px > self.max_rms:
            self.drop(f'outline fit RMS {det.fit_rms_px:.2f} px > {self.max_rms} px')
            return
        if self.frames == 1:
            self.publish(det, header, 1)
            return
        self.batch.append(det)
        if len(self.batch) == self.frames:
            avg = averaging.average([d.position for d in self.batch],
                                    [d.covariance for d in self.batch])
            det.position, det.covariance = avg.position, avg.covariance
            self.batch = []
            self.publish(det, header, avg.frames)

    def rest_fit(self, image, seed):
        """Run the rest method on an image from a seed (RestCorrection's accurate method)."""
        det = detector.detect(image, self.camera, self.radius, self.rest_method, seed,
                              self.gamma, search=False, background=self.plate)
        if det.extra.get('plate_share') is not None:
            self.get_logger().info(f'background plate of {self.plate.added} rests: in '
                                   f"{100 * det.extra['plate_share']:.0f} % of the fit's bins",
                                   throttle_duration_sec=10.0)
        return det

    def rest_seen(self, image, det, noise):
        """Add a rest's mean image to the background plate (RestCorrection's ``seen``)."""
        if self.plate is None or self.plate.shape != image.shape:
            self.plate = plate.BackgroundPlate(image.shape)
        self.plate.add_ball(image, self.camera, det.position, self.radius, noise)

    def publish(self, det, header, frames):
        self.position_pub.publish(point_stamped(det.position, header.stamp, header.frame_id))
        self.detection_pub.publish(detection_message(det, header, frames))


def main(args=None):
    return spin(SphereDetectorNode, 'sphere_detector', (ValueError, description.DescriptionError),
                args, events=True)


if __name__ == '__main__':
    sys.exit(main())
