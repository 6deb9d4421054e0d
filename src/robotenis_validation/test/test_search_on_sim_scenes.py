"""The detector's search on the simulator's renders of a ball that a pattern could outrank."""
import numpy as np
from robotenis_sim import camera_model
from robotenis_vision import camera as vision_camera
from robotenis_vision import detector

R = 0.019


def test_a_side_lit_ball_over_squares_of_its_size_is_measured_not_a_square():
    """
    Measure a side-lit ball over a checkerboard, not one of its squares.

    The ball's shadowed half is as dark as the dark squares; the checkerboard is defocused, of
    16 px squares. The rays' score ranks the squares' inscribed circles above the ball (before
    round_arc every frame measured a square) and the model fit accepts them; the ball shows its
    edge on one ellipse over a longer arc, and every frame measures it.
    """
    cam = vision_camera.default()
    c = np.array([-0.058, -0.0435, 0.184])
    light = camera_model.Lighting(direction=(0.76, 0.07, -0.645), ambient=20.0, diffuse=160.0,
                                  specular=0.0)
    board = camera_model.Background(low=30.0, high=127.0, texture=0.0, pattern='checker',
                                    square_px=15.7, phase_px=(11.1, 14.2), defocus_px=1.24)
    rng = np.random.default_rng(3)
    for _ in range(6):
        image = camera_model.render(cam, c, R, rng, lighting=light, background=board,
                                    blur_sigma=0.0, defocus_px=0.78, gamma=2.2)
        det = detector.detect(image, cam, R, gamma=2.2)
        u = det.position / np.linalg.norm(det.position)
        assert np.linalg.norm(np.cross(u, c)) < R          # its ray meets the ball
