"""The configuration as the single source of truth: every setting documented, reachable with `--set`, written
to params.json and read back exactly (`--config` replays a run); `deface presets` shows the presets."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from deface.cli import options
from deface.cli.main import app
from deface.fit import presets
from deface.fit.config import (
    RENAMED,
    FitConfig,
    Stage1Config,
    differences,
    documentation,
    flatten,
    from_dict,
    override,
    set_from_text,
    to_dict,
)


def _json_round_trip(config: FitConfig) -> FitConfig:
    return from_dict(json.loads(json.dumps(to_dict(config))))


def test_every_preset_survives_params_json():
    for name in presets.names():
        config = presets.get(name)
        assert _json_round_trip(config) == config, name


def test_params_json_of_runs_before_the_render_settings_moved_still_reads():
    """Earlier params.json files have shadows, shadow_rays, ... at the top level (RENAMED)."""
    config = override(presets.get("fast"), **{"render.shadow_rays": 48, "render.supersampling": 1})
    data = json.loads(json.dumps(to_dict(config)))
    render = data.pop("render")
    data.update({old: render[new.split(".")[1]] for old, new in RENAMED.items()})
    assert from_dict(data) == config
    assert override(config, shadow_rays=32).render.shadow_rays == 32  # old dotted paths too


def test_every_setting_is_documented_and_reachable_with_set():
    """Each path of FitConfig has a docstring, and ``--set path=<its default as printed>`` parses back to the
    same config: every value is reachable from the command line."""
    docs = documentation(FitConfig)
    assert [path for path, _, _ in docs] == list(flatten(FitConfig()))
    assert all(doc for _, _, doc in docs), [path for path, _, doc in docs if not doc]
    config = FitConfig()
    for path, default, _ in docs:
        assert set_from_text(config, f"{path}={options.show_value(default)}") == config, path


def test_command_line_order_preset_then_shortcuts_then_sets():
    config = options.fit_config("fast", None, ["lights.num_lights=4", "iterations.stage2=7"], lights=2,
                                iterations="5,6,9", priors="gp", seed=3)
    assert config.preset == "fast" and config.seed == 3
    assert config.lights.num_lights == 4 and config.iterations == type(config.iterations)(
        5, 7, 9, stage3_tolerance=presets.STAGE3_TOLERANCE, stage2_coarse_share=presets.STAGE2_COARSE_SHARE,
        stage3_holdout=presets.STAGE3_HOLDOUT)
    assert (config.priors.global_prior, config.priors.local_prior, config.priors.human_prior) == (True, False, False)
    assert options.fit_config() == presets.get("default")
    with pytest.raises(options.UsageError, match="--set resolution=x: resolution must be an integer"):
        options.fit_config("fast", None, ["resolution=x"])
    with pytest.raises(options.UsageError, match="--model"):
        options.fit_config(None, None, ["model=flame"])


def test_config_file_replays_a_params_json(tmp_path):
    config = override(presets.get("code-video"), seed=7, **{"priors.palette_samples": 500})
    (tmp_path / "params.json").write_text(json.dumps({"preset": "code-video", "config": to_dict(config)}))
    assert options.fit_config(None, tmp_path) == config
    assert options.fit_config(None, tmp_path / "params.json", ["seed=8"]) == replace(config, seed=8)
    with pytest.raises(options.UsageError, match="not both"):
        options.fit_config("fast", tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(options.UsageError, match="no params.json in that folder"):
        options.fit_config(None, tmp_path / "empty")
    with pytest.raises(options.UsageError, match="missing.json: no such file"):
        options.fit_config(None, tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(options.UsageError, match="not JSON"):
        options.fit_config(None, tmp_path / "bad.json")


def test_stage1_rigid_steps_default_to_a_quarter_at_most_80():
    assert [Stage1Config().rigid_steps(n) for n in (1, 8, 300, 400, 1000)] == [1, 2, 75, 80, 80]
    assert Stage1Config(rigid_iterations=5).rigid_steps(300) == 5


def test_fit_help_lists_every_setting():
    result = CliRunner().invoke(app, ["fit", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for path, _, _ in documentation(FitConfig):
        assert f" {path} = " in result.output, path


def test_presets_command_shows_each_preset_and_its_differences():
    result = CliRunner().invoke(app, ["presets"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    for name in presets.PRESETS:
        assert f"{name}" in result.output and presets.DESCRIPTIONS[name] in result.output, name
    assert "decouple.epsilon = 0.09  (paper: 0.17)" in result.output  # the default against the paper
    assert "tone.free_tone = false  (the default: true)" in result.output  # deface-mean-skin
    changed = differences(presets.get("fast"), presets.get("default"))
    assert set(changed) == {"preset", "resolution", "texture_size", "render.shadow_rays", "iterations.stage1",
                            "iterations.stage2", "iterations.stage3", "decouple.ace_iteration"}
    wrong = CliRunner().invoke(app, ["presets", "nope"])
    assert wrong.exit_code == 2 and "unknown preset 'nope'" in wrong.output


@pytest.mark.slow
def test_config_replays_a_finished_run_bit_exactly(photos, tmp_path):
    """`deface fit --config OUT/<input>` refits with the recorded configuration: same config, same numbers."""
    photo = str(photos / "000031.jpg")
    tiny = ["--preset", "fast", "--iterations", "30,12,4", "--quiet", "--set", "resolution=64",
            "--set", "texture_size=64", "--set", "render.shadow_rays=16", "--set", "decouple.ace_iteration=6"]
    first = CliRunner().invoke(app, ["fit", photo, "-o", str(tmp_path / "first"), *tiny])
    assert first.exit_code == 0, first.output
    replay = CliRunner().invoke(app, ["fit", photo, "-o", str(tmp_path / "replay"), "--quiet",
                                      "--config", str(tmp_path / "first" / "000031")])
    assert replay.exit_code == 0, replay.output
    params = [json.loads((tmp_path / run / "000031" / "params.json").read_text()) for run in ("first", "replay")]
    assert params[0]["config"] == params[1]["config"] and params[0]["config"]["resolution"] == 64
    arrays = [np.load(tmp_path / run / "000031" / "params.npz") for run in ("first", "replay")]
    assert sorted(arrays[0].files) == sorted(arrays[1].files)
    for name in arrays[0].files:
        assert np.array_equal(arrays[0][name], arrays[1][name]), name


def test_eval_pairs_takes_the_same_config_options(tmp_path):
    """`deface eval pairs` builds its configuration with the same options: a bad --set is a usage error."""
    result = CliRunner().invoke(app, ["eval", "pairs", str(tmp_path), "-o", str(tmp_path / "out"),
                                      "--set", "decouple.nothing=1"])
    assert result.exit_code == 2 and "decouple has no field 'nothing'" in result.output
