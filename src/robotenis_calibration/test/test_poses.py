"""Pose planning: the ball guess refined from measured rests."""
import numpy as np
import pytest

from robotenis_calibration import diagnosis, poses
from robotenis_kinematics import delta, description, synthetic
from robotenis_kinematics import identification as idf
from robotenis_sim import truth as sim_truth


def test_the_refined_guess_is_where_the_rests_saw_the_ball():
    """
    Rests of the simulator's robot (Table 1 geometry) seen through the nominal description.

    The guess is off by no more than the nominal model's effector error at those rests (the median
    of P_k + R s_k, each off by that error), where the user's guess was 5 cm off.
    """
    truth, declared = sim_truth.load(), description.nominal()
    S = truth.sphere_position - truth.camera_translation      # what the planner's guess stands for
    rough = S + np.array([0.03, -0.03, 0.03])
    P = poses.boundary(declared, rough, 12, np.random.default_rng(3))
    arm = delta.inverse(truth.geometry, P)
    Theta = truth.increments(arm, np.ones((len(P), 3)), P)
    s = (S - P) @ truth.camera_rotation                         # the true mounting (rotation only)
    guess = poses.refined_guess(declared, Theta, s)
    model_error = np.linalg.norm(delta.forward(declared, declared.theta0 + Theta) - P, axis=1)
    assert np.linalg.norm(guess - S) <= model_error.max()
    assert model_error.max() < 0.2 * np.linalg.norm(rough - S)


def test_poses_keep_the_ball_within_max_range():
    """
    Both selections plan the ball within max_range; a max_range below the nearest is refused.

    So is a ball guess that no pose of the workspace sees, after a bounded search.
    """
    truth, declared = sim_truth.load(), description.nominal()
    guess = truth.sphere_position - truth.camera_translation
    for method in poses.SELECTIONS:
        P = poses.select(method, declared, guess, 40, np.random.default_rng(4), max_range=0.35)
        z = poses.predicted_sphere(declared, guess, P)[:, 2]
        assert np.all((z >= poses.PLAN_RANGE[0]) & (z <= 0.35))
    with pytest.raises(ValueError, match='max_range'):
        poses.boundary(declared, guess, 10, np.random.default_rng(4), max_range=0.15)
    with pytest.raises(ValueError, match="move the ball into the camera's reach"):
        poses.select('discriminating', declared, guess + [0.0, 0.0, 2.0], 40,
                     np.random.default_rng(4))


def test_the_central_pose_comes_first_and_sees_the_ball_through_a_wrong_depth():
    """
    A ball 13 cm nearer than planned and 5 cm across.

    The guess is 4 cm off, and the camera's offset that the planner ignores adds the simulator's
    10 cm along the optical axis.

    Many of the planned poses then show the ball cut by the border of the 640x480 view (f = 500
    px: tan 0.64 and 0.48 across); the first one, the least off axis, does not.
    """
    truth, declared = sim_truth.load(), description.nominal()
    S = truth.sphere_position - truth.camera_translation
    error = np.array([0.03, -0.02, 0.02]) + truth.camera_translation
    P = poses.boundary(declared, S + error, 90, np.random.default_rng(5), max_range=0.4)
    first = poses.central_first(declared, S + error, P)
    assert sorted(map(tuple, first)) == sorted(map(tuple, P))
    x, y, z = poses.predicted_sphere(declared, S, first).T
    R = declared.sphere_radius
    seen = (z > 0) & (np.abs(x) + R < 0.64 * z) & (np.abs(y) + R < 0.48 * z)
    assert seen[0] and seen.mean() < 0.8


def effect_information(declared, P):
    """
    Return {named effect: log det of what its columns add beyond every other column} at poses P.

    The information of the paper's 15 parameters and every named effect's (poses.DISCRIMINATED)
    together, each effect's block taken as its Schur complement: what the score test that tells it
    from the others has to work with.
    """
    model = synthetic.true_model(declared)
    model = idf.Model(model.desc, model.P0, {n: np.zeros(3) for n in poses.DISCRIMINATED
                                             if n != 'base_geometry'})
    # the base's H beside h is not identifiable on any poses: the base is its angles here
    blocks = {n: ('phi2', 'phi3') if n == 'base_geometry'
              else diagnosis.candidate_parameters(n) for n in poses.DISCRIMINATED}
    names = idf.PAPER_PARAMETERS + tuple(p for b in blocks.values() for p in b)
    rows = poses.pose_rows(model, synthetic.measure(declared, P), names)
    info = np.einsum('kip,kiq->pq', rows, rows)
    out = {}
    for name, block in blocks.items():
        inside = np.isin(names, block)
        A, B, C = info[inside][:, inside], info[inside][:, ~inside], info[~inside][:, ~inside]
        out[name] = np.linalg.slogdet(A - B @ np.linalg.solve(C, B.T))[1]
    return out


def test_a_discriminating_design_tells_the_named_effects_apart_better():
    """
    90 poses within 0.40 m of the simulator's ball, three designs from the same pool's seed.

    The discriminating design exists to make every named effect's own information, beyond the
    geometry and the other effects, larger than the paper's random boundary poses and the
    15-parameter D-optimal design leave it: it must, for each effect, drawn from the same field
    as they are. From its own narrower field (DESIGN_FIELD) its every ball lies in that field.
    """
    truth, declared = sim_truth.load(), description.nominal()
    guess = truth.sphere_position - truth.camera_translation
    designs = {method: poses.select(method, declared, guess, 90, np.random.default_rng(6),
                                    max_range=0.40) for method in poses.SELECTIONS}
    assert np.all(poses.off_axis(declared, guess, designs['discriminating'])
                  <= poses.DESIGN_FIELD + 1e-12)
    designs['discriminating'] = poses.discriminating(declared, guess, 90,
                                                     np.random.default_rng(6), max_range=0.40,
                                                     field=1.0)
    found = {method: effect_information(declared, P) for method, P in designs.items()}
    for name in poses.DISCRIMINATED:
        for other in ('boundary', 'optimal'):
            assert found['discriminating'][name] > found[other][name], (name, other, found)
