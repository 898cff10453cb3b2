"""Presets: the default is the documented `deface` preset, which differs from `paper` only where BENCHMARKS.md
says why."""

from __future__ import annotations

from deface.fit import presets
from deface.fit.config import flatten


def test_default_is_the_deface_preset():
    assert presets.get("default") == presets.get("deface")
    assert presets.get("default").preset == "deface"


def test_deface_differs_from_paper_only_where_benchmarks_md_says_why():
    paper, deface = flatten(presets.get("paper")), flatten(presets.get("deface"))
    changed = {key: deface[key] for key in paper if paper[key] != deface[key]}
    assert changed == {"preset": "deface", "decouple.face_region": False, "decouple.epsilon": 0.09,
                       "lights.num_lights": 3, "decouple.fourier_frequencies": presets.FOURIER_OCTAVES,
                       "texture_pyramid.levels": presets.TEXTURE_LEVELS, "completion.enabled": True,
                       "iterations.stage3_tolerance": presets.STAGE3_TOLERANCE, "tone.free_tone": True,
                       "tone.scene_light_prior": True, "decouple.clipped_as_bound": True,
                       "tone.learning_rate": presets.TONE_STEP,
                       "iterations.stage2_coarse_share": presets.STAGE2_COARSE_SHARE,
                       "learning_rates.stage3_diffuse_level": presets.DIFFUSE_STEP_LEVEL,
                       "weights.diffuse_level": presets.DIFFUSE_STEP_LEVEL,
                       "iterations.stage3_holdout": presets.STAGE3_HOLDOUT,
                       "weights.landmarks": presets.STAGE2_LANDMARKS, "weights.landmark_units": "face",
                       "priors.global_prior": False, "priors.local_prior": False,
                       "shading_evidence.strength": presets.SHADING_EVIDENCE,
                       "skin_classifier.hull_margin": presets.SKIN_CLASSIFIER.hull_margin,
                       "skin_classifier.beard_zone": presets.SKIN_CLASSIFIER.beard_zone}


def test_mean_skin_is_deface_without_the_skin_tone_work():
    deface, mean_skin = flatten(presets.get("deface")), flatten(presets.get("deface-mean-skin"))
    changed = {key: mean_skin[key] for key in deface if deface[key] != mean_skin[key]}
    assert changed == {"preset": "deface-mean-skin", "tone.free_tone": False, "tone.scene_light_prior": False,
                       "decouple.clipped_as_bound": False, "tone.learning_rate": 0.3,
                       "iterations.stage2_coarse_share": 0.0, "learning_rates.stage3_diffuse_level": 0.0,
                       "iterations.stage3_holdout": 0.0, "weights.diffuse_level": 0.0}


def test_baselines_keep_the_model_mean_skin_and_free_lights():
    """NextFace's and the paper's numbers must not move with the skin-tone work."""
    for name in ("deface-mean-skin", "paper", "nextface", "nextface-star", "code-images", "code-video",
                 "code-portrait"):
        tone = presets.get(name).tone
        assert not tone.free_tone and not tone.scene_light_prior, name
        assert presets.get(name).weights.smooth_departure == 0.0, name
        assert presets.get(name).iterations.stage3_holdout == 0.0, name


def test_every_preset_renders_stage_3_antialiased_without_the_loss_blur():
    for name in presets.names():
        config = presets.get(name)
        assert config.render.supersampling == 2 and config.render.render_blur is False, name
