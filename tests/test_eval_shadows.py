"""Synthetic shadow benchmark: determinism, physical properties of the shadows, the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import typer
from PIL import Image
from typer.testing import CliRunner

from deface.eval.shadows import (
    CANVAS,
    SHAPE_KINDS,
    ShadowConfig,
    draw_occluder,
    face_region,
    make_shadow_benchmark,
    shade,
    synthesize_shadow,
    warm_light,
)
from deface.io.images import srgb_to_linear


def _photo(path: Path, size: int = 160) -> Path:
    """A skin-coloured gradient 'photo' with texture (deterministic)."""
    rng = np.random.default_rng(7)
    ys, xs = np.mgrid[0:size, 0:size] / size
    base = np.stack([0.85 - 0.2 * ys, 0.6 - 0.15 * ys + 0.05 * xs, 0.5 - 0.1 * xs], -1)
    image = np.clip(base + rng.normal(0, 0.02, base.shape), 0, 1)
    Image.fromarray(np.rint(image * 255).astype(np.uint8)).save(path)
    return path


def _silhouette(path: Path) -> Path:
    canvas = np.zeros((200, 120), np.uint8)
    canvas[20:180, 30:90] = 255
    Image.fromarray(canvas).save(path)
    return path


@pytest.fixture
def photos(tmp_path) -> list[Path]:
    return [_photo(tmp_path / "alice.png"), _photo(tmp_path / "bob.jpg", 128)]


def _config(tmp_path) -> ShadowConfig:
    return ShadowConfig(silhouettes=(str(_silhouette(tmp_path / "sil.png")),))


def _bytes(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes_different_seed_differs(tmp_path, photos):
    config = _config(tmp_path)
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        make_shadow_benchmark(photos, tmp_path / name, seed=seed, per_photo=2, use_mediapipe=False,
                              config=config)
    a, b, c = (_bytes(tmp_path / n) for n in "abc")
    assert a == b
    assert set(a) == set(c) and a["alice-00/source.png"] != c["alice-00/source.png"]
    assert a["alice-00/target.png"] == c["alice-00/target.png"]
    # a sample does not depend on which other photos are in the run
    make_shadow_benchmark(photos[:1], tmp_path / "d", seed=3, per_photo=2, use_mediapipe=False, config=config)
    assert _bytes(tmp_path / "d")["alice-01/source.png"] == a["alice-01/source.png"]


def test_benchmark_layout_target_untouched_source_darker(tmp_path, photos):
    out = tmp_path / "bench"
    config = _config(tmp_path)
    manifest = make_shadow_benchmark(photos, out, seed=0, per_photo=3, use_mediapipe=False, config=config)
    assert json.loads((out / "manifest.json").read_text()) == json.loads(json.dumps(manifest))
    names = [f"{stem}-{k:02d}" for stem in ("alice", "bob") for k in range(3)]
    assert [p["name"] for p in manifest["pairs"]] == names
    for pair in manifest["pairs"]:
        folder = out / pair["name"]
        photo = photos[0] if pair["photo"] == "alice.png" else photos[1]
        original = np.asarray(Image.open(photo).convert("RGB"))
        target = np.asarray(Image.open(folder / "target.png"))
        source = np.asarray(Image.open(folder / "source.png"))
        matte = np.asarray(Image.open(folder / "shadow_mask.png"))
        if pair["photo"] == "alice.png":  # lossless input: the target is the photo, bit for bit
            np.testing.assert_array_equal(target, original)
        assert source.shape == target.shape and matte.shape == target.shape[:2]
        assert (source <= target).all()  # uint8 sRGB order == linear RGB order (monotone decoding)
        assert (source < target).any() and np.abs(source.astype(int) - target)[matte == 0].max() == 0
        assert 0.2 <= pair["keep"] <= 0.6
        assert 0.15 <= pair["coverage"] <= 0.5
        assert pair["kind"] in SHAPE_KINDS


def test_penumbra_is_redder_than_umbra():
    """Subsurface scattering: at the shadow edge red light leaks in, so R/B of the attenuation rises."""
    target = np.full((200, 200, 3), 0.7, np.float32)
    region = np.zeros((200, 200), bool)
    region[40:160, 50:150] = True
    config = ShadowConfig(kinds=("hat",), tint=(1.0, 1.0), noise=(0.0, 0.0), coverage=(0.3, 0.5),
                          receiver=(9, 10))  # no fade-out: isolate the edge colour
    checked = 0
    for seed in range(4):
        sample = synthesize_shadow(target, region, np.random.default_rng(seed), config)
        ratio = srgb_to_linear(sample.source) / srgb_to_linear(target)  # per-channel light kept
        red_vs_blue = np.log(ratio[..., 0] / ratio[..., 2])
        umbra = sample.matte > 0.97
        # the inner penumbra (shadow side of the edge): there red light scattered in from the lit side;
        # on the lit side of the edge the opposite, smaller-in-ratio effect (slightly cyan) happens
        penumbra = (sample.matte > 0.5) & (sample.matte < 0.9)
        assert abs(float(np.median(red_vs_blue[umbra]))) < 0.03  # neutral tint: umbra nearly uncoloured
        assert red_vs_blue[penumbra].mean() > red_vs_blue[umbra].mean() + 0.01
        assert red_vs_blue.max() > 0.05  # the reddest edge pixels are visibly red
        checked += int(umbra.any() and penumbra.any())
    assert checked == 4


def test_every_occluder_kind_draws_something(tmp_path):
    sil = (str(_silhouette(tmp_path / "s.png")),)
    for kind in SHAPE_KINDS:
        canvas, params = draw_occluder(kind, np.random.default_rng(0), sil)
        assert canvas.dtype == np.uint8 and 0.01 < (canvas > 127).mean() < 0.99, kind
        json.dumps(params)
    with pytest.raises(ValueError, match="unknown occluder kind"):
        draw_occluder("cloud", np.random.default_rng(0))
    with pytest.raises(ValueError, match="needs silhouette files"):
        draw_occluder("silhouette", np.random.default_rng(0))


def test_real_photo_shadow_falls_on_the_face(shared):
    from deface.io.images import load_image, resize_max

    photo, _ = resize_max(load_image(shared / "data" / "images" / "nextface-s7.png"), 256)
    region, how = face_region(photo)
    assert how == "mediapipe" and 0.2 < region.mean() < 0.9
    config = ShadowConfig(kinds=("fingers", "hat"))
    sample = synthesize_shadow(photo, region, np.random.default_rng(0), config)
    assert 0.15 <= sample.params["coverage"] <= 0.5
    darkened = srgb_to_linear(photo).sum(-1) - srgb_to_linear(sample.source).sum(-1)
    assert darkened[region].sum() > 0.5 * darkened.sum()  # most of the lost light is on the face


def test_cli_make_shadows(tmp_path, photos):
    from deface.cli.bench import register

    app = typer.Typer()
    register(app)
    app.command("noop")(lambda: None)  # a second command keeps `bench` a sub-command group
    out = tmp_path / "cli"
    args = ["bench", "make-shadows", *map(str, photos), "-o", str(out), "--seed", "5", "--per-photo", "1",
            "--no-mediapipe", "--silhouettes", str(tmp_path)]
    _silhouette(tmp_path / "sil.png")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["seed"] == 5 and len(manifest["pairs"]) == 2
    assert (out / "bob-00" / "source.png").is_file()
    result = CliRunner().invoke(app, ["bench", "make-shadows", str(tmp_path / "missing.png"), "-o", str(out)])
    assert result.exit_code != 0 and "not found" in result.output


@pytest.mark.parametrize("kind", ["stripes", "dapples"])
def test_the_extra_occluder_kinds_draw_within_the_plane(kind):
    canvas, params = draw_occluder(kind, np.random.default_rng(3))
    assert canvas.shape == (CANVAS, CANVAS) and 0.1 < (canvas > 127).mean() < 0.95 and params


def test_a_cool_fill_under_a_warm_key_makes_the_shadow_bluer_than_the_lit_skin():
    skin = np.full((64, 64, 3), (0.8, 0.6, 0.5), np.float32)
    warm = warm_light(skin, 0.8)
    assert warm[0, 0, 2] / warm[0, 0, 0] < skin[0, 0, 2] / skin[0, 0, 0]  # a warm key: less blue than red
    matte = np.zeros((64, 64, 3), np.float32)
    matte[:, 32:] = 1.0
    shaded = shade(warm, matte, keep=0.4, tint=np.array([0.55, 0.75, 1.0]))
    lit, shadow = shaded[0, 0], shaded[0, 40]
    assert shadow[2] / shadow[0] > lit[2] / lit[0] and shadow.mean() < lit.mean()
    np.testing.assert_allclose(shaded[:, :32], warm[:, :32], atol=1e-5)  # unshadowed: the warm photo
