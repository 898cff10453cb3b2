"""The ITA measure: known CIELAB values, the UV boxes, lit-skin selection, and the benchmark's figures."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage.color import lab2rgb

from deface.eval.tone_benchmark import PROXY, TonePhoto, read_manifest, report_markdown, summary, with_proxy
from deface.io.images import linear_to_srgb, srgb_to_linear
from deface.models.ita import (
    TONE_BOXES,
    in_tone_boxes,
    ita_degrees,
    ita_group,
    ita_of_srgb,
    lit_skin,
    photo_tone,
    pixel_uvs,
    texture_ita,
    texture_tone,
    texture_tone_mask,
)


@pytest.mark.parametrize("lab, expected", [((50.0, 10.0, 20.0), 0.0), ((60.0, 5.0, 10.0), 45.0),
                                           ((40.0, 12.0, 10.0), -45.0), ((70.0, 8.0, 0.0), 90.0),
                                           ((67.32, 10.0, 10.0), 60.0)])
def test_ita_of_known_cielab_values(lab, expected):
    assert ita_degrees(np.array(lab)) == pytest.approx(expected, abs=0.01)


def test_ita_of_srgb_pixels_round_trips_through_cielab():
    """Skin colours made in CIELAB and encoded to sRGB read back with their ITA (median of a noisy patch)."""
    rng = np.random.default_rng(0)
    for ita in (-30.0, 0.0, 25.0, 55.0):
        angle = np.radians(ita)
        lab = np.array([50 + 22 * np.sin(angle), 11.0, 22 * np.cos(angle)])
        patch = lab + rng.normal(0, 0.5, (400, 3))
        srgb = lab2rgb(patch[None])[0]
        assert ita_of_srgb(srgb) == pytest.approx(ita, abs=1.0)


def test_tone_boxes_are_cheeks_and_forehead_of_the_layout():
    mask = texture_tone_mask(200, 200)
    assert mask[:, :100].sum() == pytest.approx(mask[:, 100:].sum(), rel=0.05)  # both cheeks, mirrored
    rows = np.nonzero(mask.any(1))[0]
    assert rows.min() == pytest.approx(200 * TONE_BOXES["forehead"][2], abs=1)  # forehead on top (y down)
    assert rows.max() == pytest.approx(200 * TONE_BOXES["left_cheek"][3], abs=1.5)
    assert in_tone_boxes(np.array([0.5, 1 - 0.17]))  # forehead centre, v up
    assert not in_tone_boxes(np.array([0.5, 0.5]))  # the nose


def test_texture_ita_reads_only_the_boxes():
    lab_skin = np.array([45.0, 12.0, 18.0])  # ITA -15.5
    texture = np.ones((128, 128, 3))  # white outside the boxes must not count
    texture[texture_tone_mask(128, 128)] = lab2rgb(lab_skin[None, None])[0, 0]
    assert texture_ita(texture) == pytest.approx(float(ita_degrees(lab_skin)), abs=0.5)


def test_lit_skin_leaves_out_shadow_and_highlights():
    lit = np.full((100, 3), [0.7, 0.5, 0.4])
    shadow = np.full((60, 3), [0.35, 0.25, 0.2])  # half as bright in sRGB: ~4.6x darker in luminance
    clipped = np.full((10, 3), [1.0, 0.9, 0.8])
    keep = lit_skin(np.concatenate([lit, shadow, clipped]))
    assert keep[:100].all() and not keep[100:].any()


def test_photo_tone_measures_the_pixels_showing_the_boxes():
    """A photo whose forehead pixels hold one skin colour and everything else another."""
    uv = np.zeros((64, 64, 2))
    uv[..., 0] = np.linspace(0, 1, 64)[None, :]
    uv[..., 1] = np.linspace(1, 0, 64)[:, None]
    skin = lab2rgb(np.array([[[62.0, 11.0, 15.0]]]))[0, 0]
    photo = np.full((64, 64, 3), 0.1)
    inside = in_tone_boxes(uv)
    photo[inside] = skin
    covered = np.ones((64, 64), bool)
    tone = photo_tone(photo, uv, covered, covered)
    assert tone.pixels == inside.sum()
    assert tone.ita == pytest.approx(float(ita_degrees(np.array([62.0, 11.0, 15.0]))), abs=0.5)
    assert np.isnan(photo_tone(photo, uv, covered, np.zeros_like(covered)).ita)  # no skin: no tone


def test_pixel_uvs_interpolate_the_mesh_uvs(shared):
    from deface.models import load_face_model
    from deface.render.camera import Camera
    from deface.render.mesh import Mesh
    from deface.render.renderer import Renderer

    model = load_face_model("ict")
    mesh = Mesh.create(model.mean_shape, model.triangles, model.uvs, model.triangle_uvs)
    camera = Camera.frontal(64, 64, distance=60.0, fov_degrees=34.0)
    fragments = Renderer().rasterize(mesh, camera)
    uv = pixel_uvs(fragments, mesh)
    covered = fragments.mask.numpy() > 0
    assert uv[covered].min() >= 0 and uv[covered].max() <= 1 and (uv[~covered] == 0).all()
    centre = uv[32, 32]  # the nose: on the midline of the symmetric layout
    assert centre[0] == pytest.approx(0.5, abs=0.02)
    assert torch.is_tensor(fragments.mask)


def test_manifest_errors_are_one_line(tmp_path):
    with pytest.raises(ValueError, match="no MANIFEST.tsv"):
        read_manifest(tmp_path)
    (tmp_path / "MANIFEST.tsv").write_text("file\tgroup\na.png\tdark\n")
    with pytest.raises(ValueError, match="missing column"):
        read_manifest(tmp_path)
    (tmp_path / "MANIFEST.tsv").write_text("file\ttone_group\na.png\tdark\n")
    with pytest.raises(ValueError, match="missing a.png"):
        read_manifest(tmp_path)


def test_a_manifest_gives_each_photo_its_own_settings(tmp_path):
    """A card's box per photo (benchmarks/tone_truth.py writes them), ``;``-separated; none where the column is
    empty or absent."""
    (tmp_path / "images").mkdir()
    for name in ("a.png", "b.png"):
        (tmp_path / "images" / name).write_bytes(b"")
    (tmp_path / "MANIFEST.tsv").write_text("file\ttone_group\tgt_ita\tsettings\n"
                                           "a.png\tdark\t-10\ttone.illuminant.reference_box=0.7,0.5,0.9,0.7; "
                                           "tone.illuminant.reference_reflectance=0.9\n"
                                           "b.png\tlight\t50\t\n")
    first, second = read_manifest(tmp_path)
    assert first.settings == ("tone.illuminant.reference_box=0.7,0.5,0.9,0.7",
                              "tone.illuminant.reference_reflectance=0.9")
    assert second.settings == () and second.gt_ita == 50.0


def test_summary_figures_follow_their_definitions():
    photos = [TonePhoto(f"{g}{i}.png", g, ita) for g, itas in
              (("dark", (-20.0, 0.0)), ("medium", (20.0, 30.0)), ("light", (50.0, 60.0))) for i, ita in enumerate(itas)]
    kept = {p.stem: {"albedo_ita": p.gt_ita + 2.0, "photo_ita": float("nan"), "speckle": float(len(p.stem)),
                     "detail": 1.0 if p.group == "dark" else 0.5} for p in photos}
    figures = summary(photos, kept)
    assert figures["mae"] == pytest.approx(2.0) and figures["bias"] == pytest.approx(0.0)
    assert figures["group_speckle"] == pytest.approx({"dark": 5.0, "medium": 7.0, "light": 6.0})
    assert figures["group_detail"] == pytest.approx({"dark": 1.0, "medium": 0.5, "light": 0.5})
    assert figures["slope"] == pytest.approx(1.0) and figures["spearman"] == pytest.approx(1.0)
    flat = {p.stem: {"albedo_ita": 45.0, "photo_ita": float("nan")} for p in photos}
    figures = summary(photos, flat)  # one tone for everybody; records cached before speckle was measured
    assert all(np.isnan(v) for v in [*figures["group_speckle"].values(), *figures["group_detail"].values()])
    assert figures["slope"] == pytest.approx(0.0, abs=1e-9)
    assert figures["group_mae"]["dark"] == pytest.approx(55.0) and figures["bias"] > 15


@pytest.mark.parametrize("ita, group", [(70.0, "very light"), (55.0, "light"), (41.5, "light"),
                                        (30.0, "intermediate"), (10.0, "brown"), (10.1, "tan"), (-30.0, "dark"),
                                        (-29.9, "brown"), (-60.0, "dark")])
def test_ita_groups_follow_del_bino(ita, group):
    assert ita_group(ita) == group


def skin_map(lab: tuple[float, float, float], size: int = 64) -> np.ndarray:
    """A diffuse map [size, size, 3], linear RGB, of one CIELAB colour."""
    return np.broadcast_to(srgb_to_linear(lab2rgb(np.array([[lab]]))[0, 0]), (size, size, 3)).copy()


@pytest.mark.parametrize("lab", [(68.0, 10.0, 15.0), (53.5, 12.0, 19.5), (40.0, 10.0, 17.5)])
def test_the_tone_interval_is_the_map_under_a_light_level_one_sigma_off(lab):
    diffuse = skin_map(lab)
    tone = texture_tone(diffuse, 0.4)
    assert tone["texture_ita"] == pytest.approx(ita_degrees(np.array(lab)), abs=0.3)
    darker, lighter = tone["ita_interval"]
    assert darker < tone["texture_ita"] < lighter
    # independently: the ITA of the whole map made exp(-+0.4) as light, as a W exp(+-0.4) as bright would make it
    assert darker == pytest.approx(texture_ita(linear_to_srgb(diffuse * np.exp(-0.4))), abs=0.02)
    assert lighter == pytest.approx(texture_ita(linear_to_srgb(diffuse * np.exp(0.4))), abs=0.02)
    assert texture_tone(diffuse, 0.0)["ita_interval"] == pytest.approx([tone["texture_ita"]] * 2, abs=0.02)
    assert texture_tone(diffuse, None)["ita_interval"] is None
    wider = texture_tone(diffuse, 0.8)["ita_interval"]
    assert wider[0] < darker and wider[1] > lighter
    assert tone["ita_interval_2sigma"] == pytest.approx(wider, abs=1e-6)  # two sigma: the interval of 2 x 0.4


@pytest.mark.parametrize("lab", [(68.0, 10.0, 15.0), (40.0, 10.0, 17.5)])
def test_a_grayscale_photo_gives_no_tone_only_a_note(lab):
    """The map of a grayscale photo has the model's colour, not the person's: no ITA, no interval."""
    diffuse = skin_map(lab)
    colour = linear_to_srgb(diffuse)
    grey = np.repeat(colour.mean(-1, keepdims=True), 3, axis=-1)
    assert texture_tone(diffuse, 0.4, colour)["texture_ita"] == pytest.approx(texture_tone(diffuse, 0.4)["texture_ita"])
    tone = texture_tone(diffuse, 0.4, grey)
    assert tone["texture_ita"] is None and tone["ita_interval"] is None and "grayscale" in tone["note"]


def test_a_dark_skins_interval_is_wider_for_the_same_light_level_spread():
    """ITA moves further per unit of L* near L* = 50 than on a light skin (docs/skin-tone.md, Limits)."""
    widths = [np.ptp(texture_tone(skin_map(lab), 0.3)["ita_interval"]) for lab in ((68.0, 10.0, 15.0),
                                                                                   (46.5, 12.0, 19.5))]
    assert widths[1] > 1.3 * widths[0]


def test_interval_figures_count_the_references_inside():
    photos = [TonePhoto(f"p{i}.png", g, ita) for i, (g, ita) in enumerate((("dark", 0.0), ("light", 50.0),
                                                                             ("light", 40.0)))]
    records = {"p0": {"albedo_ita": 5.0, "ita_interval": [-5.0, 15.0]},  # truth inside
               "p1": {"albedo_ita": 58.0, "ita_interval": [52.0, 62.0]},  # outside
               "p2": {"albedo_ita": 41.0, "ita_interval": [35.0, 45.0]}}  # inside
    figures = summary(photos, records)
    assert figures["in_interval"] == pytest.approx(2 / 3) and figures["interval_width"] == pytest.approx(40 / 3)
    assert figures["interval_median_width"] == pytest.approx(10.0) and np.isnan(figures["in_interval_2sigma"])
    records["p1"]["ita_interval_2sigma"] = [46.0, 68.0]  # the two-sigma interval holds p1's truth
    records["p0"]["ita_interval_2sigma"] = [-15.0, 25.0]
    assert summary(photos, records)["in_interval_2sigma"] == pytest.approx(1.0)  # p2's, not recorded, not counted
    without = summary(photos, {k: {"albedo_ita": v["albedo_ita"]} for k, v in records.items()})
    assert np.isnan(without["in_interval"]) and np.isnan(without["interval_width"])


def test_proxy_is_scored_against_the_truth_only_where_it_is_known():
    photos = [TonePhoto(f"p{i}.png", g, ita) for i, (g, ita) in enumerate((("dark", -10.0), ("light", 50.0)))]
    fits = {"default": {"p0": {"albedo_ita": -8.0, "photo_ita": 5.0, "speckle": 0.1, "detail": 0.9},
                        "p1": {"albedo_ita": 53.0, "photo_ita": 40.0, "speckle": 0.0, "detail": 0.8}}}
    scored = with_proxy(photos, fits)
    assert summary(photos, scored[PROXY])["group_mae"] == pytest.approx({"dark": 15.0, "light": 10.0})
    section = report_markdown(photos, fits, "synthetic", "deface bench skin-tone ...")
    assert f"| {PROXY} | 12.5 | 15.0 | 10.0 |" in section and "| p0.png | dark | -10.0 | -8.0 | 5.0 |" in section
    real = [TonePhoto(p.file, p.group, None) for p in photos]
    assert PROXY not in with_proxy(real, fits) and f"| {PROXY} |" not in report_markdown(real, fits, "photos", "...")
