"""
`./robotenis detect --camera-info FILE IMAGE...`: the sphere centre in each image, one line each.

Prints ``x,y,z`` (m, optical frame: x right, y down, z forward) per image, in the order given. The
ball's radius is ``--radius`` (m), or the ``sphere_radius`` of ``--description`` (a robot
description YAML; default: the nominal one). An image that cannot be read, is not 8-bit mono,
shows no ball, a ball cut by the border or two balls (ambiguous: which one?) gets a message on
stderr naming the file and no line; the others are still measured, and the exit status is then 1
(2 for a bad option or camera file).
"""
import argparse
import os
import sys

import cv2
import numpy as np

from robotenis_vision import camera as camera_model
from robotenis_vision import detector


def read_image(path):
    """Read a mono 8-bit image as a 2-D array; ValueError naming the problem."""
    if not os.path.isfile(path):
        raise ValueError('no such file')
    image = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError('cannot read the image (empty or not an image file)')
    if image.ndim == 3:
        colour = image[..., :3]
        if not (np.array_equal(colour[..., 0], colour[..., 1])
                and np.array_equal(colour[..., 0], colour[..., 2])):
            raise ValueError(f'a colour image ({image.shape[2]} channels): the detector measures '
                             "the camera's mono images (convert it to grey first)")
        image = np.ascontiguousarray(colour[..., 0])
    if image.dtype != np.uint8:
        raise ValueError(f'a {8 * image.dtype.itemsize}-bit image: expected 8-bit mono')
    return image


def radius_of(args):
    """Return the ball's radius (m) from --radius or the description's sphere_radius."""
    if args.radius is not None:
        return args.radius
    from robotenis_kinematics import description
    if args.description is None:
        return description.nominal().sphere_radius
    return description.load(args.description).sphere_radius


def main(argv=None):
    parser = argparse.ArgumentParser(prog='detect', description=__doc__.strip().split('\n')[0])
    parser.add_argument('--camera-info', required=True,
                        help='ROS camera_info YAML (camera_calibration_parsers format)')
    size = parser.add_mutually_exclusive_group()
    size.add_argument('--radius', type=float, default=None, help='sphere radius, m')
    size.add_argument('--description', default=None,
                      help='robot description YAML whose sphere_radius is used '
                           '(default: the nominal description)')
    parser.add_argument('--method', choices=detector.METHODS, default='model')
    parser.add_argument('--gamma', type=float, default=1.0,
                        help="the camera's response: grey = 255 (I / 255)^(1 / gamma) "
                             '(default 1, a linear camera)')
    parser.add_argument('images', nargs='+')
    args = parser.parse_args(argv)
    try:            # the messages here say what is wrong with a file; OpenCV's warnings repeat it
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:
        pass
    try:
        camera = camera_model.load(args.camera_info)
        radius = radius_of(args)
    except (camera_model.CameraError, ValueError) as e:
        print(f'detect: {e}', file=sys.stderr)
        return 2
    if not radius > 0 or not args.gamma > 0:
        print(f'detect: the radius and gamma must be positive, got {radius}, {args.gamma}',
              file=sys.stderr)
        return 2
    failed = 0
    for path in args.images:
        try:
            d = detector.detect(read_image(path), camera, radius, args.method, gamma=args.gamma)
        except (ValueError, detector.DetectionError) as e:
            print(f'{path}: {e}', file=sys.stderr)
            failed += 1
            continue
        x, y, z = d.position
        print(f'{x:.9f},{y:.9f},{z:.9f}', flush=True)
    if failed:
        print(f'detect: {failed} of {len(args.images)} images without a measurement',
              file=sys.stderr)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
