"""Stage 1: L_lan, batched projection, synthetic round trips (photo and video), a real photo."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from deface.fit.stage1 import Stage1Config, fit_landmarks, project_points
from deface.landmarks.correspondence import correspondence_for, landmark_basis
from deface.landmarks.detect import Landmarks
from deface.losses.landmarks import landmark_distances, landmark_loss
from deface.render.camera import Camera

SIZE = (512, 448)  # (W, H)


def rotation_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between axis-angle rotations [..., 3] (ambiguous near pi as vectors: compare matrices)."""
    from deface.render.camera import axis_angle_to_matrix

    ra = axis_angle_to_matrix(torch.as_tensor(a, dtype=torch.float64))
    rb = axis_angle_to_matrix(torch.as_tensor(b, dtype=torch.float64))
    trace = (ra.transpose(-1, -2) @ rb).diagonal(dim1=-2, dim2=-1).sum(-1)
    return torch.arccos(((trace - 1) / 2).clamp(-1, 1)).numpy()


def test_landmark_loss_values_and_scale_invariance():
    detected = torch.zeros(1, 3, 2)
    projected = torch.tensor([[[3.0, 4.0], [0.0, 0.0], [6.0, 8.0]]])  # distances 5, 0, 10
    assert landmark_loss(projected, detected, scale=1.0) == pytest.approx(5.0, rel=1e-4)
    weights = torch.tensor([1.0, 0.0, 1.0])
    assert landmark_loss(projected, detected, scale=5.0, weights=weights) == pytest.approx(1.5, rel=1e-4)
    assert landmark_loss(projected, detected, scale=1.0, squared=True) == pytest.approx(125 / 3, rel=1e-4)
    # Doubling the resolution (pixels and scale) leaves the loss unchanged.
    assert landmark_loss(2 * projected, detected, scale=2.0) == pytest.approx(5.0, rel=1e-4)
    # Finite gradient at a zero distance.
    point = torch.zeros(1, 1, 2, requires_grad=True)
    landmark_distances(point, torch.zeros(1, 1, 2)).sum().backward()
    assert torch.isfinite(point.grad).all()
    with pytest.raises(ValueError):
        landmark_loss(projected, torch.zeros(1, 2, 2), scale=1.0)


def test_project_points_matches_camera():
    rng = np.random.default_rng(0)
    points = torch.as_tensor(rng.normal(size=(2, 5, 3)), dtype=torch.float32)
    rotation = torch.tensor([[math.pi, 0.1, 0.0], [3.0, -0.2, 0.3]])
    translation = torch.tensor([[1.0, 2.0, 50.0], [-1.0, 0.0, 70.0]])
    focal = torch.tensor(600.0)
    batched = project_points(points, rotation, translation, focal, SIZE)
    for t in range(2):
        camera = Camera(focal, rotation[t], translation[t], *SIZE)
        torch.testing.assert_close(batched[t], camera.project(points[t])[0])


@pytest.fixture(scope="module")
def ict(shared):
    from deface.models.ict import load_ict

    return load_ict()


def _synthetic(ict, corr, rotation, translation, identity, expression, focal=900.0, noise=0.1, seed=0):
    """Landmarks of T frames projected from known parameters, plus Gaussian pixel noise."""
    mean, id_basis, ex_basis = landmark_basis(ict, corr)
    points = (
        mean + np.einsum("k,knc->nc", identity, id_basis) + np.einsum("tk,knc->tnc", expression, ex_basis)
    )
    pixels = project_points(
        torch.as_tensor(points, dtype=torch.float32),
        torch.as_tensor(rotation, dtype=torch.float32),
        torch.as_tensor(translation, dtype=torch.float32),
        torch.tensor(focal),
        SIZE,
    ).numpy()
    rng = np.random.default_rng(seed)
    detections = []
    for frame in pixels:
        full = np.full((478, 2), np.nan, np.float32)  # unused points must not matter
        full[corr.mediapipe_ids] = frame + rng.normal(scale=noise, size=frame.shape)
        full[[33, 263]] = np.nan_to_num(full[[33, 263]])
        detections.append(Landmarks(full, np.zeros(478, np.float32), SIZE, 1, 0))
    return pixels, detections


def test_synthetic_photo_round_trip(ict):
    corr = correspondence_for(ict)
    rng = np.random.default_rng(4)
    identity = rng.normal(size=ict.num_identity).astype(np.float32) * 0.7
    expression = np.zeros((1, ict.num_expression), np.float32)
    expression[0, ict.expression_names.index("jawOpen")] = 0.3
    expression[0, ict.expression_names.index("mouthSmile_L")] = 0.5
    rotation = np.array([[math.pi - 0.15, 0.3, 0.05]])  # looking up-ish, turned by 17 degrees
    translation = np.array([[2.0, -1.0, 55.0]])
    truth, detections = _synthetic(ict, corr, rotation, translation, identity, expression)
    result = fit_landmarks(ict, corr, detections, SIZE, Stage1Config())
    assert result.residual_px[0] < 0.6  # noise is 0.1 px per axis; priors cost a little
    assert np.abs(result.projected_2d[0] - truth[0]).max() < 2.5
    assert rotation_gap(result.rotation[0], rotation[0]) < 0.05  # rad
    assert result.expression.min() >= 0 and result.expression.max() <= 1
    assert result.error_iod[0] < 0.01
    assert result.loss_history[-1] < result.loss_history[0] / 5


def test_synthetic_video_shares_identity(ict):
    corr = correspondence_for(ict)
    identity = np.random.default_rng(5).normal(size=ict.num_identity).astype(np.float32) * 0.5
    expression = np.zeros((3, ict.num_expression), np.float32)
    expression[1, ict.expression_names.index("jawOpen")] = 0.6
    rotation = np.array([[math.pi, 0.0, 0.0], [math.pi, 0.25, 0.0], [math.pi - 0.1, -0.2, 0.1]])
    translation = np.array([[0.0, 0.0, 60.0], [1.0, 0.0, 62.0], [-1.0, 1.0, 58.0]])
    truth, detections = _synthetic(ict, corr, rotation, translation, identity, expression, seed=1)
    result = fit_landmarks(ict, corr, detections, SIZE, Stage1Config())
    assert result.identity.shape == (ict.num_identity,) and result.expression.shape == (3, ict.num_expression)
    assert result.rotation.shape == (3, 3) and result.landmarks_2d.shape == (3, len(corr), 2)
    assert (result.residual_px < 0.6).all()
    assert rotation_gap(result.rotation, rotation).max() < 0.05
    jaw = ict.expression_names.index("jawOpen")
    assert result.expression[1, jaw] > result.expression[0, jaw] + 0.2  # the open mouth is in frame 1


def _yawed(yaw_degrees: float) -> np.ndarray:
    """Axis-angle of a frontal upright face (rotation (pi, 0, 0)) turned by ``yaw_degrees`` about its up axis."""
    from deface.render.camera import axis_angle_to_matrix

    frontal = axis_angle_to_matrix(torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64)).numpy()
    turned = frontal @ axis_angle_to_matrix(torch.tensor([0.0, math.radians(yaw_degrees), 0.0],
                                                          dtype=torch.float64)).numpy()
    angle = math.acos((np.trace(turned) - 1) / 2)
    axis = np.array([turned[2, 1] - turned[1, 2], turned[0, 2] - turned[2, 0], turned[1, 0] - turned[0, 1]])
    return axis / np.linalg.norm(axis) * angle  # angle near pi: the antisymmetric part still gives the axis


@pytest.mark.slow
def test_three_yaws_give_a_shape_closer_than_any_one_of_them(ict):
    """Issue 59: a head seen at yaw -30, 0 and +30 degrees, each view's landmarks with its own detector noise
    (5 px per axis on a face of about 300 px). The shape fitted to the three together is closer to the truth at the
    landmark points (after the best similarity) than the shape fitted to any one of them, on every head."""
    from deface.eval.albedo_benchmark import similarity_aligned

    corr = correspondence_for(ict)
    mean, id_basis, _ = landmark_basis(ict, corr)

    def shape_error(truth_identity, fitted_identity) -> float:
        truth = (mean + np.einsum("k,knc->nc", truth_identity, id_basis)).astype(np.float64)
        fitted = (mean + np.einsum("k,knc->nc", fitted_identity, id_basis)).astype(np.float64)
        return float(np.median(np.linalg.norm(similarity_aligned(fitted, truth) - truth, axis=1)))

    rotation = np.stack([_yawed(yaw) for yaw in (-30.0, 0.0, 30.0)])
    translation = np.tile([0.0, 0.0, 55.0], (3, 1))
    expression = np.zeros((3, ict.num_expression), np.float32)
    joint_errors, best_alone = [], []
    for head in range(3):
        identity = np.random.default_rng(100 + head).normal(size=ict.num_identity).astype(np.float32) * 0.7
        _, detections = _synthetic(ict, corr, rotation, translation, identity, expression, noise=5.0, seed=head)
        alone = [shape_error(identity, fit_landmarks(ict, corr, [d], SIZE).identity) for d in detections]
        joint = shape_error(identity, fit_landmarks(ict, corr, detections, SIZE).identity)
        assert joint < min(alone), (head, joint, alone)
        joint_errors.append(joint)
        best_alone.append(min(alone))
    assert np.mean(joint_errors) < 0.9 * np.mean(best_alone)  # not a tie: the views' noise averages out


def test_real_photo_fit(ict, photos):
    from deface.io import load_image
    from deface.landmarks.detect import detect_landmarks

    image = load_image(photos / "nextface-s2.png")
    landmarks = detect_landmarks(image)
    corr = correspondence_for(ict)
    result = fit_landmarks(ict, corr, [landmarks], landmarks.image_size, Stage1Config(), iterations=200)
    assert result.error_iod[0] < 0.03
    # Upright, facing the camera: the model's +y (up) maps to image up, +z (toward viewer) to the camera.
    camera = result.camera(0)
    up = camera.rotation_matrix @ torch.tensor([0.0, 1.0, 0.0])
    toward_viewer = camera.rotation_matrix @ torch.tensor([0.0, 0.0, 1.0])
    assert up[1] < -0.8 and toward_viewer[2] < -0.8


def test_bad_input_raises(ict):
    corr = correspondence_for(ict)
    with pytest.raises(ValueError, match="one Landmarks per frame"):
        fit_landmarks(ict, corr, [None], SIZE)
    with pytest.raises(ValueError, match="rigid_iterations"):
        fit_landmarks(ict, corr, [object()], SIZE, Stage1Config(rigid_iterations=20), iterations=10)
