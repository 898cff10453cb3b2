"""Presets: FitConfig's defaults are the shipped method (`deface`, the default preset), and every other preset is
the defaults with the differences deface/fit/presets.py lists for it."""

from __future__ import annotations

from dataclasses import replace

import pytest

from deface.fit import presets
from deface.fit.config import FitConfig, differences, flatten, override


def test_default_is_the_deface_preset_and_the_defaults():
    assert presets.get("default") == presets.get("deface")
    assert presets.get("default").preset == "deface"
    assert presets.get("deface") == replace(FitConfig(), preset="deface") and presets.PRESETS["deface"] == {}


@pytest.mark.parametrize("name", list(presets.PRESETS))
def test_each_preset_is_the_default_plus_its_listed_differences(name):
    listed = presets.PRESETS[name]
    config, default = presets.get(name), FitConfig()
    assert config == override(replace(default, preset=name), **listed)
    changed = {path: mine for path, (mine, _) in differences(config, default).items() if path != "preset"}
    # what it lists is what differs, but for entries that restate a default: the authors' full code configs, and
    # the NextFace baselines' no g and no GP/LP after the paper's
    assert changed == {path: value for path, value in listed.items() if flatten(default)[path] != value}


def test_paper_is_table_6():
    config = presets.get("paper")
    w = config.weights
    assert (w.photometric, w.landmarks, w.segmentation, w.area, w.binary, w.global_prior, w.local_prior,
            w.human_prior) == (2e3, 1e-3, 1.5e2, 0.5, 25, 2e3, 2.0, 1.0)  # w0..w7
    assert (config.iterations.stage2, config.iterations.stage3, config.decouple.ace_iteration) == (400, 200, 100)
    assert (config.decouple.epsilon, config.lights.num_lights, config.lights.init) == (0.17, 5, "paper")
    assert config.decouple.light_masks and config.decouple.face_region
    assert config.priors.global_prior and config.priors.local_prior and config.priors.human_prior


def test_fast_is_deface_with_fewer_steps_keeping_its_other_iteration_settings():
    deface, fast = presets.get("deface"), presets.get("fast")
    assert fast.iterations == replace(deface.iterations, stage1=150, stage2=150, stage3=60)


def test_mean_skin_is_deface_without_the_skin_tone_work():
    deface, mean_skin = flatten(presets.get("deface")), flatten(presets.get("deface-mean-skin"))
    changed = {key: mean_skin[key] for key in deface if deface[key] != mean_skin[key]}
    assert changed == {"preset": "deface-mean-skin", "tone.free_tone": False, "tone.scene_light_prior": False,
                       "decouple.clipped_as_bound": False, "tone.learning_rate": 0.3,
                       "iterations.stage2_coarse_share": 0.0, "learning_rates.stage3_diffuse_level": 0.0,
                       "iterations.stage2_frames_per_step": 0,
                       "iterations.stage3_holdout": 0.0, "weights.diffuse_level": 0.0, "chroma.enabled": False,
                       "shade_level.enabled": False, "pigment_gamut.enabled": False}


def test_baselines_keep_the_model_mean_skin_and_free_lights():
    """NextFace's and the paper's numbers must not move with the skin-tone work."""
    for name in ("deface-mean-skin", "paper", "nextface", "nextface-star", "code-images", "code-video",
                 "code-portrait"):
        tone = presets.get(name).tone
        assert not tone.free_tone and not tone.scene_light_prior, name
        assert presets.get(name).weights.smooth_departure == 0.0, name
        assert presets.get(name).iterations.stage3_holdout == 0.0, name
        assert not presets.get(name).chroma.enabled, name
        assert not presets.get(name).shade_level.enabled, name
        assert not presets.get(name).pigment_gamut.enabled, name


def test_every_preset_renders_stage_3_antialiased_without_the_loss_blur():
    for name in presets.names():
        config = presets.get(name)
        assert config.render.supersampling == 2 and config.decouple.render_blur is False, name


def test_a_preset_with_a_misspelt_path_or_a_wrong_type_fails_when_written():
    """Presets are checked when deface/fit/presets.py is imported (``_checked``), naming the preset."""
    with pytest.raises(ValueError, match="preset 'typo'.*epsilonn"):
        presets._checked({"typo": {"decouple.epsilonn": 0.1}})
    with pytest.raises(ValueError, match="preset 'wrong'.*decouple.epsilon"):
        presets._checked({"wrong": {"decouple.epsilon": "high"}})
    assert presets._checked({"fine": {"decouple.epsilon": 0.1}}) == {"fine": {"decouple.epsilon": 0.1}}
