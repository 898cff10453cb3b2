"""The configuration as the single source of truth: every setting documented, reachable with `--set`, written
to params.json and read back exactly (`--config` replays a run); `deface presets` shows the presets."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from deface.cli import options
from deface.cli.main import app
from deface.fit import presets, user_options
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


def test_params_json_of_runs_before_the_settings_moved_still_reads():
    """Earlier params.json files have shadows, shadow_rays, ... at the top level, and later ones the fit's
    shadow refresh and render blur under "render" (RENAMED): both read as today's config."""
    config = override(presets.get("fast"), **{"render.shadow_rays": 48, "render.supersampling": 1,
                                              "iterations.shadow_refresh_every": 7, "decouple.render_blur": True})
    current = json.loads(json.dumps(to_dict(config)))
    top_level, nested = json.loads(json.dumps(current)), json.loads(json.dumps(current))
    for old, new in RENAMED.items():
        group, name = new.split(".")
        data = nested if "." in old else top_level
        value = data[group].pop(name)
        if "." in old:
            data["render"][name] = value
        else:
            data[old] = value
    assert "render_blur" in nested["render"] and "render_blur" in top_level
    assert from_dict(top_level) == config and from_dict(nested) == config
    assert override(config, shadow_rays=32).render.shadow_rays == 32  # old dotted paths too
    assert override(config, **{"render.render_blur": False}).decouple.render_blur is False


def test_params_json_written_with_the_former_defaults_replays_as_it_ran():
    """Until issue 41 FitConfig's defaults were the paper's, and a params.json written before a setting existed
    leaves it out: it replays with the value it ran with (the paper's, presets.PAPER), not today's default.
    The fixture is a real `deface` run's config from before the shading evidence and skin_classifier groups."""
    recorded = json.loads((Path(__file__).parent / "fixtures" / "params_before_issue41.json").read_text())["config"]
    config = from_dict(recorded)
    former = override(FitConfig(), **presets.PAPER)
    left_out = set(flatten(config)) - _paths(recorded)
    assert {"shading_evidence.strength", "skin_classifier.beard_zone", "skin_classifier.hull_margin"} <= left_out
    assert all(flatten(config)[path] == flatten(former)[path] for path in left_out)
    assert (config.shading_evidence.strength, config.skin_classifier.beard_zone) == (0.0, False)
    assert config.preset == "deface" and config.priors.global_prior and config.weights.smooth_departure == 1000.0
    assert from_dict({}) == former and former.preset == "custom"


def _paths(data: dict, prefix: str = "") -> set[str]:
    paths = set()
    for key, value in data.items():
        paths |= _paths(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}"}
    return paths


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
    config = user_options.fit_config("fast", None, ["lights.num_lights=4", "iterations.stage2=7"], lights=2,
                                iterations="5,6,9", priors="gp", seed=3)
    assert config.preset == "fast" and config.seed == 3
    assert config.lights.num_lights == 4
    assert config.iterations == replace(presets.get("fast").iterations, stage1=5, stage2=7, stage3=9)
    assert (config.priors.global_prior, config.priors.local_prior, config.priors.human_prior) == (True, False, False)
    assert user_options.fit_config() == presets.get("default")
    with pytest.raises(user_options.UsageError, match="--set resolution=x: resolution must be an integer"):
        user_options.fit_config("fast", None, ["resolution=x"])
    with pytest.raises(user_options.UsageError, match="--model"):
        user_options.fit_config(None, None, ["model=flame"])


def test_config_file_replays_a_params_json(tmp_path):
    config = override(presets.get("code-video"), seed=7, **{"priors.palette_samples": 500})
    (tmp_path / "params.json").write_text(json.dumps({"preset": "code-video", "config": to_dict(config)}))
    assert user_options.fit_config(None, tmp_path) == config
    assert user_options.fit_config(None, tmp_path / "params.json", ["seed=8"]) == replace(config, seed=8)
    with pytest.raises(user_options.UsageError, match="not both"):
        user_options.fit_config("fast", tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(user_options.UsageError, match="no params.json in that folder"):
        user_options.fit_config(None, tmp_path / "empty")
    with pytest.raises(user_options.UsageError, match="missing.json: no such file"):
        user_options.fit_config(None, tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(user_options.UsageError, match="not JSON"):
        user_options.fit_config(None, tmp_path / "bad.json")


def test_stage1_rigid_steps_default_to_a_quarter_at_most_80():
    assert [Stage1Config().rigid_steps(n) for n in (1, 8, 300, 400, 1000)] == [1, 2, 75, 80, 80]
    assert Stage1Config(rigid_iterations=5).rigid_steps(300) == 5


def test_fit_help_lists_every_setting():
    result = CliRunner().invoke(app, ["fit", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for path, _, _ in documentation(FitConfig):
        assert f" {path} = " in result.output, path


def test_presets_command_shows_each_preset_and_exactly_its_differences():
    result = CliRunner().invoke(app, ["presets"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    blocks, name = {}, None
    for line in result.output.splitlines():
        if not line.startswith(" "):
            name = line.split(":")[0].removesuffix(" (the default)")
            assert presets.DESCRIPTIONS[name] in " ".join(result.output.split()), name
            blocks[name] = []
        else:
            blocks[name].append(line.strip())
    assert list(blocks) == list(presets.PRESETS)
    default = presets.get("default")
    assert blocks["deface"] == ["the defaults of every setting (`deface fit --help` lists them)"]
    for name, lines in blocks.items():
        if name != "deface":
            changed = [path for path in differences(presets.get(name), default) if path != "preset"]
            assert [line.split(" = ")[0] for line in lines] == changed, name
    assert "decouple.epsilon = 0.17  (the default: 0.09)" in blocks["paper"]
    assert "tone.free_tone = false  (the default: true)" in blocks["deface-mean-skin"]
    assert {line.split(" = ")[0] for line in blocks["fast"]} == {
        "resolution", "texture_size", "render.shadow_rays", "iterations.stage1", "iterations.stage2",
        "iterations.stage3", "decouple.ace_iteration"}
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
