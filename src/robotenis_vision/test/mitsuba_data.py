"""Read the committed Mitsuba 3 sets of test/data: their index, truths, cameras and images."""
import os

import cv2
import numpy as np
from robotenis_vision import camera
import yaml


def index(folder):
    """Return the entries of a set's index.yaml."""
    with open(os.path.join(folder, 'index.yaml')) as f:
        return yaml.safe_load(f)['images']


def truth_and_camera(folder, scene_id):
    """Return a scene's truth (NNN.yaml) and the camera it was rendered with."""
    with open(os.path.join(folder, f'{scene_id}.yaml')) as f:
        truth = yaml.safe_load(f)
    return truth, camera.Camera(np.array(truth['K']), np.array(truth['D']), truth['width'],
                                truth['height'], 'mitsuba')


def image(folder, name):
    """Return a set's 8-bit image as stored."""
    return cv2.imread(os.path.join(folder, name), cv2.IMREAD_UNCHANGED)
