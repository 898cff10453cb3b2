"""Fields f and g, pixel coordinates, ACE selection and composition."""

from __future__ import annotations

import pytest
import torch

from deface.decouple import (
    FaceRegionField,
    LightMaskField,
    ace_select,
    compose_face,
    composite,
    fourier_features,
    frame_time,
    light_areas,
    pixel_coordinates,
    renormalise,
    video_coordinates,
)


def test_pixel_coordinates_paper_convention_spans_minus_one_to_one():
    coords = pixel_coordinates(4, 8, t=0.25)
    assert coords.shape == (4, 8, 3)
    assert coords[0, 0, 0] == pytest.approx(-1 + 1 / 8) and coords[0, -1, 0] == pytest.approx(1 - 1 / 8)
    assert coords[0, 0, 1] == pytest.approx(-1 + 1 / 4) and coords[-1, 0, 1] == pytest.approx(1 - 1 / 4)
    assert torch.all(coords[..., 2] == 0.25)


def test_pixel_coordinates_code_convention_divides_by_height():
    coords = pixel_coordinates(4, 8, convention="code")
    assert coords[0, 0, :2].tolist() == [-1.0, -1.0]
    assert coords[0, 7, 0] == pytest.approx(2 * 7 / 4 - 1)  # wider than tall: x runs past 1
    assert coords[3, 0, 1] == pytest.approx(2 * 3 / 4 - 1)


def test_frame_time_and_video_coordinates():
    assert frame_time(0, 1) == 0.0 and frame_time(3, 4) == 0.75
    coords = video_coordinates(3, 2, 2)
    assert coords.shape == (3, 2, 2, 3)
    assert coords[:, 0, 0, 2].tolist() == pytest.approx([0.0, 1 / 3, 2 / 3])
    with pytest.raises(ValueError):
        frame_time(4, 4)


def test_light_mask_field_softmax_and_architecture():
    torch.manual_seed(0)
    field = LightMaskField(5)
    widths = [(m.in_features, m.out_features) for m in field.mlp if isinstance(m, torch.nn.Linear)]
    assert widths == [(3, 16), (16, 64), (64, 64), (64, 5)]
    masks = field(video_coordinates(2, 6, 7))
    assert masks.shape == (2, 6, 7, 5)
    assert torch.all(masks >= 0)
    assert torch.allclose(masks.sum(-1), torch.ones(2, 6, 7), atol=1e-6)


def test_kept_lights_renormalise_and_survive_state_dict():
    torch.manual_seed(1)
    field = LightMaskField(4)
    coords = pixel_coordinates(3, 5)
    full = field(coords)
    field.keep([2, 0])
    kept = field(coords)
    expected = full[..., [2, 0]] / full[..., [2, 0]].sum(-1, keepdim=True)
    assert torch.allclose(kept, expected, atol=1e-6)
    assert torch.allclose(renormalise(full, [2, 0]), expected, atol=1e-6)
    clone = LightMaskField(4)
    clone.load_state_dict(field.state_dict())
    assert clone.kept == [2, 0] and torch.allclose(clone(coords), kept)
    with pytest.raises(ValueError):
        field.keep([0, 0])


def test_fourier_option_changes_input_width_only():
    field = LightMaskField(3, fourier_frequencies=4)
    assert field.mlp[0].in_features == 3 * 9
    assert field(pixel_coordinates(2, 2)).shape == (2, 2, 3)


@pytest.mark.slow
def test_uniform_start_gives_every_light_an_equal_mask_until_a_gradient_splits_them():
    torch.manual_seed(0)
    field = LightMaskField(3, fourier_frequencies=4, uniform_start=True)
    coords = pixel_coordinates(16, 16)
    assert torch.allclose(field(coords), torch.full((16, 16, 3), 1.0 / 3.0))
    left = coords[..., 0] < 0  # the photo says: light 0 on the left half, light 2 on the right
    optimiser = torch.optim.Adam(field.parameters(), lr=0.01)
    for _ in range(50):
        masks = field(coords)
        loss = -(masks[..., 0][left].log().mean() + masks[..., 2][~left].log().mean())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    masks = field(coords).detach()
    assert masks[..., 0][left].mean() > 0.6 and masks[..., 2][~left].mean() > 0.6


def test_fourier_features_hold_the_input_and_sin_cos_octaves():
    coords = torch.tensor([[0.25, -0.5, 0.0]])
    encoded = fourier_features(coords, 2)
    assert encoded.shape == (1, 3 * 5) and torch.equal(encoded[:, :3], coords)
    x_angles = torch.tensor([0.25 * torch.pi, 0.5 * torch.pi])  # 2^k pi x for k = 0, 1
    torch.testing.assert_close(encoded[0, 3:7], torch.cat([torch.sin(x_angles), torch.cos(x_angles)]))


def _stripe_fit_error(fourier_frequencies: int) -> float:
    """Mean squared error of f fitted (100 Adam steps) to two-light masks of 8 blind slats across the image."""
    torch.manual_seed(0)
    coords = pixel_coordinates(32, 32)
    shadowed = (torch.sin(coords[..., 1] * 8 * torch.pi) > 0).float()  # [H, W], slats 1/8 of the height
    target = torch.stack([1 - shadowed, shadowed], dim=-1)  # [H, W, 2]
    field = LightMaskField(2, fourier_frequencies=fourier_frequencies)
    optimiser = torch.optim.Adam(field.parameters(), lr=0.01)
    for _ in range(100):
        optimiser.zero_grad()
        loss = ((field(coords) - target) ** 2).mean()
        loss.backward()
        optimiser.step()
    return loss.item()


def test_fourier_features_let_f_draw_thin_stripes_the_raw_mlp_cannot():
    # Why the default preset encodes f's input: blinds and fingers cast shadows thinner than the raw MLP's reach.
    raw, encoded = _stripe_fit_error(0), _stripe_fit_error(4)
    assert encoded < 1e-3 and raw > 0.1  # 0.25 = no better than a constant half-half mask


def test_face_region_field_shapes_range_and_architecture():
    torch.manual_seed(0)
    field = FaceRegionField()
    assert field.conv.kernel_size == (5, 5) and field.conv.in_channels == 3 and field.conv.out_channels == 16
    widths = [(m.in_features, m.out_features) for m in field.mlp if isinstance(m, torch.nn.Linear)]
    assert widths == [(16, 64), (64, 64), (64, 1)]
    prob = field(video_coordinates(2, 8, 9))
    assert prob.shape == (2, 8, 9)
    assert torch.all((prob > 0) & (prob < 1))
    assert field(pixel_coordinates(8, 9)).shape == (8, 9)


def test_gradients_reach_both_fields():
    torch.manual_seed(0)
    f, g = LightMaskField(3), FaceRegionField()
    coords = video_coordinates(1, 6, 6)
    target = torch.rand(1, 6, 6, 3)
    loss = ((f(coords) - target) ** 2).mean() + g(coords).mean()
    loss.backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in f.parameters())
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in g.parameters())


def _masks_with_areas(areas: list[float]) -> torch.Tensor:
    """[1, n, 2, 5] masks whose per-light mean over the 10 pixels equals ``areas`` (constant maps)."""
    return torch.tensor(areas)[None, :, None, None].expand(1, len(areas), 2, 5).clone()


def test_ace_keeps_large_masks_sorted_by_area():
    masks, coverage = _masks_with_areas([0.3, 0.5, 0.2]), torch.ones(1, 2, 5)
    assert light_areas(masks, coverage).tolist() == pytest.approx([0.3, 0.5, 0.2])
    assert ace_select(masks, coverage, epsilon=0.25) == [1, 0]
    assert ace_select(masks, coverage, epsilon=0.1) == [1, 0, 2]


def test_ace_keeps_everything_when_none_qualifies():
    masks, coverage = _masks_with_areas([0.3, 0.5, 0.2]), torch.ones(1, 2, 5)
    assert ace_select(masks, coverage, epsilon=0.6) == [0, 1, 2]


def test_ace_area_normalisers_differ_by_coverage_fraction():
    coverage = torch.zeros(1, 2, 5)
    coverage[:, :, :2] = 1.0  # 4 of 10 pixels
    masks = coverage[:, None] * torch.tensor([0.7, 0.3])[None, :, None, None]  # M_N = M_R f
    assert light_areas(masks, coverage, "render_mask").tolist() == pytest.approx([0.7, 0.3])
    assert light_areas(masks, coverage, "image").tolist() == pytest.approx([0.28, 0.12])
    assert ace_select(masks, coverage, 0.2, "render_mask") == [0, 1]
    assert ace_select(masks, coverage, 0.2, "image") == [0]


def test_compose_and_composite_by_hand():
    renders = torch.stack([torch.full((2, 2, 3), 1.0), torch.full((2, 2, 3), 3.0)])  # [K=2, 2, 2, 3]
    masks = torch.stack([torch.full((2, 2), 0.25), torch.full((2, 2), 0.75)])
    face = compose_face(renders, masks)
    assert torch.allclose(face, torch.full((2, 2, 3), 0.25 + 2.25))
    video = compose_face(renders[None].expand(3, -1, -1, -1, -1), masks[None].expand(3, -1, -1, -1))
    assert video.shape == (3, 2, 2, 3)
    image = torch.zeros(2, 2, 3)
    region = torch.tensor([[1.0, 0.0], [0.5, 0.0]])
    out = composite(face, image, region)
    assert out[0, 0, 0] == pytest.approx(2.5) and out[1, 0, 0] == pytest.approx(1.25) and out[0, 1, 0] == 0
    with pytest.raises(ValueError):
        compose_face(renders, masks[:1])


def test_face_region_field_masked_matches_full_evaluation():
    import torch

    from deface.decouple.coords import pixel_coordinates
    from deface.decouple.fields import FaceRegionField

    torch.manual_seed(0)
    field = FaceRegionField()
    coords = pixel_coordinates(12, 10)
    mask = torch.rand(12, 10) > 0.4
    full = field(coords)
    masked = field.masked(coords, mask)
    assert torch.allclose(masked[mask], full[mask], atol=1e-6)
    assert torch.all(masked[~mask] == 0)
