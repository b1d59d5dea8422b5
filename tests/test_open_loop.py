"""Open-loop odometry (``odometry.open_loop``, ``tools.open_loop``) against the simulator's truth.

The state follows the true motion, so the returned poses are the truth; each frame's own
estimate is kept beside them and must be as close to the true motion as a registration
against a true-pose map makes it.
"""

from __future__ import annotations

import numpy as np
import pytest

from odometry.config import variant
from odometry.open_loop import run_open_loop as odometry_open_loop
from odometry.pipeline import OdometryError
from scenes import build_scene
from simlidar import se3
from simlidar.in_memory import simulate_in_memory
from simlidar.sensor import load_sensor
from tools.open_loop import open_loop_errors, run_open_loop
from tools.worlds import world_of_scene


@pytest.fixture(scope="module")
def city_frames():
    scene = build_scene("city", seed=0)
    return simulate_in_memory(world_of_scene(scene, "scene:city"), scene.trajectory, load_sensor("vlp16"), 12,
                              seed=0, t_start=5.0, name="city-vlp16")


def test_open_loop_state_follows_the_truth_and_keeps_each_estimate(city_frames):
    seq = city_frames
    truth = se3.inverse(seq.poses[0]) @ seq.poses
    result = odometry_open_loop(seq, variant("salo-map"), seq.poses)
    run = result.run
    np.testing.assert_allclose(run.poses, truth, atol=1e-9)  # the state took the true motion
    assert np.isnan(result.estimated_motions[0]).all()
    errors = open_loop_errors(seq.poses, result.estimated_motions, run.diagnostics)
    moved = errors.travelled_m
    assert moved.min() > 0.5  # the car moves: a frozen estimate would err by its motion
    assert not errors.extrapolated.any()
    # every frame's own estimate, against a map of true poses, within a few centimetres of the truth,
    # and its own: not the true motion the state took
    assert np.max(errors.translation_m) < 0.03
    assert np.max(errors.rotation_deg) < 0.3
    assert np.min(errors.translation_m) > 1e-5
    # the city constrains every direction, by the truth's normals and by the registrations' own
    truth = min(d.translation_eigenvalues[0] for d in seq.degeneracy)
    threshold = variant("salo-map").degeneracy.degenerate_eigenvalue
    assert truth > threshold
    np.testing.assert_array_equal(errors.weakest_information,
                                  [d.translation_eigenvalues[0] for d in run.diagnostics[1:]])
    assert np.all(errors.weakest_information > threshold)


def test_open_loop_errors_measure_a_known_bias(city_frames):
    """An estimate 2 cm short of every true motion shows as -2 cm along track, -2 cm x frames / distance."""
    seq = city_frames
    true = se3.inverse(seq.poses[:-1]) @ seq.poses[1:]

    class Diag:
        def __init__(self, extrapolated=False):
            self.extrapolated = extrapolated
            self.translation_eigenvalues = np.array([0.2, 0.3, 0.5])

    short = true.copy()
    unit = true[:, :3, 3] / np.linalg.norm(true[:, :3, 3], axis=1, keepdims=True)
    short[:, :3, 3] -= 0.02 * unit
    estimates = np.concatenate([np.full((1, 4, 4), np.nan), short])
    errors = open_loop_errors(seq.poses, estimates, [Diag() for _ in estimates])
    np.testing.assert_allclose(errors.along_m, -0.02, atol=1e-9)
    np.testing.assert_allclose(errors.translation_m, 0.02, atol=1e-9)
    assert errors.along_bias_pct == pytest.approx(-100 * 0.02 * len(true) / errors.travelled_m.sum())
    # an extrapolated frame's "estimate" (the guess) is left out of the errors
    marked = open_loop_errors(seq.poses, estimates, [Diag()] + [Diag(k == 3) for k in range(len(short))])
    assert np.isnan(marked.translation_m[3]) and np.isnan(marked.along_m[3])
    assert marked.extrapolated.sum() == 1
    assert np.isnan(marked.weakest_information[3])
    np.testing.assert_array_equal(np.delete(marked.weakest_information, 3), 0.2)
    with pytest.raises(ValueError, match="11 frame diagnostics for 12 true poses"):
        open_loop_errors(seq.poses, estimates, [Diag() for _ in estimates[:-1]])
    with pytest.raises(ValueError, match="11 estimated motions for 12 true poses"):
        open_loop_errors(seq.poses, estimates[:-1], [Diag() for _ in estimates])


def test_open_loop_through_the_tool_and_a_wrong_number_of_poses(city_frames):
    errors = run_open_loop(city_frames, city_frames.poses, "default")
    assert len(errors.translation_m) == len(city_frames) - 1
    with pytest.raises(OdometryError, match="11 true poses for 12 frames"):
        odometry_open_loop(city_frames, variant("bl"), city_frames.poses[:-1])
