"""Stage 1: pose, focal length, identity and expression fitted to the detected landmarks.

Loss: ``L_lan`` (:func:`deface.losses.landmarks.landmark_loss`, mean 2D distance over the
correspondence points divided by a size in pixels) + ``w_id * mean(alpha²)`` (identity N(0, 1)) +
``w_ex * mean(beta)`` (blendshape weights kept in [0, 1] by projection after every Adam step; a PCA
expression model gets ``mean(beta²)`` and no box). For a video, identity and focal are shared by all
frames and pose and expression are per frame.

Steps:
1. Initial pose per frame from the model's mean-shape landmarks with ``cv2.solvePnP`` (EPnP, then
   Levenberg-Marquardt) at a fixed initial focal length (``initial_fov_degrees`` on the longest side).
2. ``rigid_iterations`` Adam steps (``Stage1Config`` in deface/fit/config.py) on pose and focal only, then
   the remaining steps on everything
   (coarse to fine). All in float32 on the landmark points only: the model is restricted once to the
   N correspondence points (exact, the model is linear), so a step costs O(T * N * (Ki + Ke)).

Camera: :class:`deface.render.camera.Camera` (OpenCV convention, principal point at the image centre unless
given, e.g. the photo's centre seen from a crop around the face; axis-angle rotation model -> camera); a
frontal upright face has rotation close to (pi, 0, 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch

from deface.fit.config import Stage1Config
from deface.fit.guard import StepGuard
from deface.landmarks.correspondence import Correspondence, landmark_basis
from deface.landmarks.detect import Landmarks
from deface.losses.landmarks import blendshape_prior, identity_prior, landmark_loss, pca_expression_prior
from deface.models.base import FaceModel
from deface.render.camera import Camera, axis_angle_to_matrix

# MediaPipe indices of the outer eye corners (subject's right, subject's left): the inter-ocular distance.
OUTER_EYE_CORNERS = (33, 263)


@dataclass(frozen=True)
class Stage1Result:
    """The fitted parameters, and how well they explain the landmarks."""

    identity: np.ndarray  # [Ki] float32
    expression: np.ndarray  # [T, Ke] float32
    rotation: np.ndarray  # [T, 3] axis-angle model -> camera
    translation: np.ndarray  # [T, 3] cm
    focal: np.ndarray  # [] pixels
    landmarks_2d: np.ndarray  # [T, N, 2] detected points (correspondence order), pixels
    projected_2d: np.ndarray  # [T, N, 2] fitted model points projected, pixels
    residual_px: np.ndarray  # [T] mean distance projected <-> detected over the N points, pixels
    iod_px: np.ndarray  # [T] detected inter-ocular distance (outer eye corners 33-263), pixels
    iod_frontal_px: (
        np.ndarray
    )  # [T] fitted 3D outer-eye-corner distance * focal / depth: IOD without yaw shrink
    image_size: tuple[int, int]  # (W, H)
    loss_history: np.ndarray  # [iterations] total loss per step
    principal_point: tuple[float, float] | None = None  # (x, y) pixels; None: the image centre

    @property
    def error_iod(self) -> np.ndarray:
        """[T] mean landmark error as a fraction of the inter-ocular distance (outer eye corners)."""
        return self.residual_px / self.iod_px

    @property
    def error_iod_frontal(self) -> np.ndarray:
        """[T] mean landmark error as a fraction of the pose-free IOD (fair on profile views)."""
        return self.residual_px / self.iod_frontal_px

    def camera(self, frame: int = 0) -> Camera:
        """The fitted camera of a frame."""
        width, height = self.image_size
        return Camera(
            focal=torch.as_tensor(self.focal, dtype=torch.float32),
            rotation=torch.as_tensor(self.rotation[frame], dtype=torch.float32),
            translation=torch.as_tensor(self.translation[frame], dtype=torch.float32),
            width=width,
            height=height,
            principal_point=self.principal_point,
        )


def principal(size: tuple[int, int], principal_point: tuple[float, float] | None) -> tuple[float, float]:
    """(x, y) of the principal point of a (W, H) image: ``principal_point``, or the image centre when None."""
    return (size[0] / 2, size[1] / 2) if principal_point is None else principal_point


def project_points(
    points: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor, focal: torch.Tensor, size,
    principal_point: tuple[float, float] | None = None,
) -> torch.Tensor:
    """Batched :meth:`Camera.project`: points [T, N, 3], rotation [T, 3], translation [T, 3] -> [T, N, 2]."""
    cam = torch.einsum("tij,tnj->tni", axis_angle_to_matrix(rotation), points) + translation[:, None]
    centre = torch.tensor(principal(size, principal_point), dtype=points.dtype)
    return focal * cam[..., :2] / cam[..., 2:].clamp_min(1e-6) + centre


def initial_pose(model_points: np.ndarray, image_points: np.ndarray, focal: float, size,
                 principal_point: tuple[float, float] | None = None) -> tuple:
    """solvePnP of [N, 3] model points to [N, 2] pixels -> (rotation [3], translation [3]) or a frontal
    guess (face centred, distance from the landmark spread) when PnP fails or puts the face behind."""
    import cv2

    cx, cy = principal(size, principal_point)
    matrix = np.array([[focal, 0, cx], [0, focal, cy], [0, 0, 1]], np.float64)
    obj, img = model_points.astype(np.float64), image_points.astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, matrix, None, flags=cv2.SOLVEPNP_EPNP)
    if ok:
        ok, rvec, tvec = cv2.solvePnP(obj, img, matrix, None, rvec, tvec, True, flags=cv2.SOLVEPNP_ITERATIVE)
    if ok and np.isfinite(tvec).all() and tvec[2, 0] > 0:
        return rvec.ravel(), tvec.ravel()
    # Frontal fallback: match the spread of the points to set the distance.
    spread_model = np.linalg.norm(obj - obj.mean(0), axis=1).mean()
    spread_image = np.linalg.norm(img - img.mean(0), axis=1).mean()
    depth = focal * spread_model / max(spread_image, 1e-6)
    centre = (img.mean(0) - [cx, cy]) * depth / focal
    translation = np.array([centre[0], centre[1], depth]) - obj.mean(0) * [1, -1, -1]
    return np.array([math.pi, 0.0, 0.0]), translation


def fit_landmarks(
    model: FaceModel,
    corr: Correspondence,
    detections: Sequence[Landmarks],
    image_size: tuple[int, int],
    config: Stage1Config | None = None,
    iterations: int = 300,
    principal_point: tuple[float, float] | None = None,
    photo_side: float | None = None,
) -> Stage1Result:
    """Fit pose, focal, identity and expression to the landmarks of T frames (T = 1 for a photo).

    detections: one :class:`Landmarks` per frame (drop frames without a face beforehand);
    image_size: (W, H) of the images the landmark pixels refer to; ``iterations`` Adam steps in all;
    principal_point: (x, y) in those pixels (None: the image centre); photo_side: the longest side of the
    whole photo in those pixels, which ``initial_fov_degrees`` spans (None: max(W, H); a crop of the photo
    gives the photo's, so the initial focal length does not depend on the crop).
    """
    config = config or Stage1Config()
    if not detections or any(d is None for d in detections):
        raise ValueError("fit_landmarks needs one Landmarks per frame (drop frames without a face first)")
    rigid = config.rigid_steps(iterations)
    if not 0 <= rigid <= iterations:
        raise ValueError(f"stage1.rigid_iterations ({rigid}) must be within the stage's {iterations} iterations")
    with _single_thread():
        problem = _Problem(model, corr, detections, image_size, config, iterations, principal_point, photo_side)
        history = problem.run()
        return problem.result(history)


@contextmanager
def _single_thread():
    """Run with one intra-op thread: the tensors are tiny, and on a busy 2-core machine torch's thread
    pool made the same fit 5-10x slower (measured: 1.4 s vs 9-14 s)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


class _Problem:
    """Parameters, targets and the loss of one Stage-1 fit."""

    def __init__(self, model, corr, detections, size, config: Stage1Config, iterations: int,
                 principal_point: tuple[float, float] | None, photo_side: float | None):
        self.config, self.size, self.iterations = config, (int(size[0]), int(size[1])), iterations
        self.principal_point = principal_point
        self.photo_side = float(max(self.size) if photo_side is None else photo_side)
        self.blendshapes = model.expression_prior == "blendshape"
        mean, id_basis, ex_basis = landmark_basis(model, corr)
        self.mean = torch.as_tensor(mean)  # [N, 3]
        self.id_basis = torch.as_tensor(id_basis)  # [Ki, N, 3]
        self.ex_basis = torch.as_tensor(ex_basis)  # [Ke, N, 3]
        self.weights = torch.as_tensor(corr.weights, dtype=torch.float32)  # [N]
        self.mediapipe_ids = corr.mediapipe_ids  # [N]
        all_points = np.stack([d.points for d in detections]).astype(np.float32)  # [T, 478, 2]
        self.targets = torch.as_tensor(all_points[:, corr.mediapipe_ids])  # [T, N, 2]
        self.iod = np.linalg.norm(
            all_points[:, OUTER_EYE_CORNERS[0]] - all_points[:, OUTER_EYE_CORNERS[1]], axis=1
        )
        self.scale = self._normaliser()  # [T]
        self._init_parameters(model, mean)

    def _normaliser(self) -> torch.Tensor:
        if self.config.normalise_by == "image":
            return torch.full((len(self.targets),), float(max(self.size)))
        extent = self.targets.amax(1) - self.targets.amin(1)  # [T, 2]
        return extent.norm(dim=-1).clamp_min(1.0)

    def _init_parameters(self, model: FaceModel, mean: np.ndarray) -> None:
        frames = len(self.targets)
        focal = 0.5 * self.photo_side / math.tan(math.radians(self.config.initial_fov_degrees) / 2)
        poses = [initial_pose(mean, target.numpy(), focal, self.size, self.principal_point)
                 for target in self.targets]
        self.focal0 = focal
        self.depth0 = float(np.mean([t[2] for _, t in poses]))
        self.rotation = torch.tensor(np.stack([r for r, _ in poses]), dtype=torch.float32, requires_grad=True)
        translation = np.stack([t for _, t in poses]) / self.depth0
        self.translation = torch.tensor(translation, dtype=torch.float32, requires_grad=True)  # / depth0
        self.log_focal = torch.zeros((), requires_grad=True)  # log(focal / focal0)
        self.identity = torch.zeros(model.num_identity, requires_grad=True)
        self.expression = torch.zeros(frames, model.num_expression, requires_grad=True)

    def points(self) -> torch.Tensor:
        """Model landmarks in the model frame [T, N, 3]."""
        return (
            self.mean
            + torch.einsum("k,knc->nc", self.identity, self.id_basis)
            + torch.einsum("tk,knc->tnc", self.expression, self.ex_basis)
        )

    def project(self) -> torch.Tensor:
        """Model landmarks projected with the current parameters [T, N, 2]."""
        focal = self.focal0 * torch.exp(self.log_focal)
        return project_points(self.points(), self.rotation, self.translation * self.depth0, focal, self.size,
                              self.principal_point)

    def loss(self) -> torch.Tensor:
        config = self.config
        total = landmark_loss(self.project(), self.targets, self.scale, self.weights)
        total = total + config.identity_weight * identity_prior(self.identity)
        expression_term = blendshape_prior if self.blendshapes else pca_expression_prior
        return total + config.expression_weight * expression_term(self.expression)

    def _optimiser(self, rigid: bool) -> torch.optim.Adam:
        config = self.config
        groups = [
            {"params": [self.rotation], "lr": config.lr_rotation},
            {"params": [self.translation], "lr": config.lr_translation},
        ]
        if config.optimise_focal:
            groups.append({"params": [self.log_focal], "lr": config.lr_focal})
        if not rigid:
            groups.append({"params": [self.identity], "lr": config.lr_identity})
            groups.append({"params": [self.expression], "lr": config.lr_expression})
        return torch.optim.Adam(groups)

    def run(self) -> np.ndarray:
        history = []
        rigid_steps, total = self.config.rigid_steps(self.iterations), self.iterations
        optimiser = self._optimiser(rigid=True)
        guard = StepGuard(optimiser, "stage 1")  # NaN/Inf rollback (deface/fit/guard.py)
        for step in range(total):
            if step == rigid_steps:
                optimiser = self._optimiser(rigid=False)
                guard = StepGuard(optimiser, "stage 1")
            # Cosine decay to 10% within each phase: Adam at a constant step oscillates around the optimum.
            start, length = (0, rigid_steps) if step < rigid_steps else (rigid_steps, total - rigid_steps)
            factor = 0.1 + 0.45 * (1 + math.cos(math.pi * (step - start) / max(length, 1)))
            for group in optimiser.param_groups:
                group.setdefault("base_lr", group["lr"])
                group["lr"] = group["base_lr"] * factor
            optimiser.zero_grad(set_to_none=True)
            loss = self.loss()
            loss.backward()
            optimiser.step()
            if self.blendshapes:
                with torch.no_grad():
                    self.expression.clamp_(0.0, 1.0)
            guard.check(loss)
            history.append(float(loss.detach()))
        return np.asarray(history, np.float32)

    def _iod_frontal(self, focal: float) -> np.ndarray:
        """[T] 3D distance of the fitted outer eye corners, in pixels at their depth (nan if not used)."""
        ids = [np.flatnonzero(self.mediapipe_ids == m) for m in OUTER_EYE_CORNERS]
        if any(len(i) == 0 for i in ids):
            return np.full(len(self.targets), np.nan, np.float32)
        points = self.points()[:, [ids[0][0], ids[1][0]]]  # [T, 2, 3]
        cam = torch.einsum("tij,tnj->tni", axis_angle_to_matrix(self.rotation), points)
        depth = (cam[..., 2] + (self.translation * self.depth0)[:, None, 2]).mean(1)  # [T]
        return (focal * (points[:, 0] - points[:, 1]).norm(dim=-1) / depth).numpy().astype(np.float32)

    @torch.no_grad()
    def result(self, history: np.ndarray) -> Stage1Result:
        projected = self.project()
        distance = (projected - self.targets).norm(dim=-1)  # [T, N]
        residual = (distance * self.weights).sum(1) / self.weights.sum()
        focal = self.focal0 * math.exp(float(self.log_focal))
        return Stage1Result(
            identity=self.identity.detach().numpy().copy(),
            expression=self.expression.detach().numpy().copy(),
            rotation=self.rotation.detach().numpy().copy(),
            translation=(self.translation * self.depth0).detach().numpy().copy(),
            focal=np.asarray(focal, np.float32),
            landmarks_2d=self.targets.numpy().copy(),
            projected_2d=projected.numpy().copy(),
            residual_px=residual.numpy().astype(np.float32),
            iod_px=self.iod.astype(np.float32),
            iod_frontal_px=self._iod_frontal(focal),
            image_size=self.size,
            loss_history=history,
            principal_point=self.principal_point,
        )
