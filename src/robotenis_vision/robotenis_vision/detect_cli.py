"""
`./robotenis detect --camera-info FILE IMAGE...`: the sphere centre in each image, one line each.

Prints ``x,y,z`` (m, optical frame: x right, y down, z forward) per image, in the order given. An
image that cannot be read, or in which no sphere can be measured, gets a message on stderr and no
line; the others are still measured, and the exit status is then 1.
"""
import argparse
import os
import sys

import cv2
import numpy as np

from robotenis_vision import camera as camera_model
from robotenis_vision import detector


def default_radius():
    from robotenis_kinematics import description
    return description.nominal().sphere_radius


def read_image(path):
    """Read a mono image as a 2-D array; ValueError naming the problem."""
    if not os.path.isfile(path):
        raise ValueError('no such file')
    image = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError('cannot read the image (missing, empty or not an image file)')
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    if image.dtype != np.uint8:
        raise ValueError(f'expected an 8-bit image, got {image.dtype}')
    return image


def main(argv=None):
    parser = argparse.ArgumentParser(prog='detect', description=__doc__.strip().split('\n')[0])
    parser.add_argument('--camera-info', required=True,
                        help='ROS camera_info YAML (camera_calibration_parsers format)')
    parser.add_argument('--radius', type=float, default=None,
                        help='sphere radius, m (default: the nominal description)')
    parser.add_argument('--method', choices=detector.METHODS, default='conic')
    parser.add_argument('images', nargs='+')
    args = parser.parse_args(argv)
    try:            # the messages here say what is wrong with a file; OpenCV's warnings repeat it
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:
        pass
    try:
        camera = camera_model.load(args.camera_info)
    except camera_model.CameraError as e:
        print(f'detect: {e}', file=sys.stderr)
        return 2
    radius = args.radius if args.radius is not None else default_radius()
    if not radius > 0:
        print(f'detect: --radius must be positive, got {radius}', file=sys.stderr)
        return 2
    failed = 0
    for path in args.images:
        try:
            d = detector.detect(read_image(path), camera, radius, args.method)
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
