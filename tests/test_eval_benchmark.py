"""The benchmark harness end to end on one tiny pair (smoke schedule), and the BENCHMARKS.md rewrite."""

from __future__ import annotations

import json
import shutil

import pytest

from deface.eval.benchmark import (
    TABLES,
    VARIANTS,
    report_markdown,
    run_benchmark,
    update_benchmarks_md,
    variant_config,
)
from deface.landmarks import identity


def test_every_table_row_names_a_variant():
    assert all(name in VARIANTS for _, rows in TABLES for _, name in rows)


def _row_configs(title_start: str) -> dict:
    rows = next(rows for title, rows in TABLES if title.startswith(title_start))
    return {label: variant_config(VARIANTS[name], "quick") for label, name in rows}


def test_ablation_rows_have_the_configuration_their_label_says():
    # Rows point at "ours" where the default preset is that row, so a changed default must show up here.
    for label, config in _row_configs("Initial light conditions").items():
        assert f"n = {config.lights.num_lights}" in label, label
    switches = {label: (c.decouple.light_masks, c.decouple.face_region) for label, c in _row_configs("Neural").items()}
    assert switches == {"w/o f, w/o g": (False, False), "+ f (Ours)": (True, False), "+ g only": (False, True),
                        "+ f + g": (True, True)}
    priors = {label: (c.priors.global_prior, c.priors.local_prior) for label, c in _row_configs("Priors").items()}
    assert priors == {"NA (Ours)": (False, False), "GP": (True, False), "GP + LP": (True, True)}
    for label, config in _row_configs("One global SH").items():
        assert f"B = {config.lights.bands}" == label and config.lights.num_lights == 1


@pytest.mark.slow
def test_benchmark_smoke_run_writes_metrics_and_tables(photos, tmp_path):
    pair = tmp_path / "pairs" / "one"
    pair.mkdir(parents=True)
    shutil.copy(photos / "000031.jpg", pair / "source.jpg")
    shutil.copy(photos / "000031.jpg", pair / "target.jpg")
    out = tmp_path / "results"
    run_benchmark(tmp_path / "pairs", out, ["nextface", "ours"], schedule="smoke", jobs=1, log=lambda _: None)
    metrics = json.loads((out / "ours" / "metrics.json").read_text())
    assert metrics["pairs"][0]["name"] == "one"
    target = metrics["mean"]["target"]["face"]
    assert 5 < target["psnr"] < 60 and 0 < target["ssim"] <= 1 and target["lpips"] >= 0
    # The protocol adds the identity distance whenever dlib is installed (scripts/setup.sh installs it).
    assert ("identity" in metrics["mean"]["target"]) == identity.available()
    # Cached: a second run re-fits nothing and gives the same numbers.
    run_benchmark(tmp_path / "pairs", out, ["ours"], schedule="smoke", jobs=1, log=lambda _: None)
    assert json.loads((out / "ours" / "metrics.json").read_text()) == metrics
    # A cache fitted with another configuration (e.g. before a default changed) is refitted, not reused.
    cached = out / "ours" / "one" / "scores.json"
    stale = json.loads(cached.read_text())
    stale["config"]["lights"]["num_lights"] += 1
    stale["target"]["face"]["psnr"] = -1.0
    cached.write_text(json.dumps(stale))
    run_benchmark(tmp_path / "pairs", out, ["ours"], schedule="smoke", jobs=1, log=lambda _: None)
    assert json.loads((out / "ours" / "metrics.json").read_text()) == metrics
    report = tmp_path / "BENCHMARKS.md"
    report.write_text("# Benchmarks\n\nkept text\n")
    section = report_markdown(out, tmp_path / "pairs", "smoke", "deface bench run ...")
    update_benchmarks_md(report, section)
    update_benchmarks_md(report, section)  # idempotent: the section is replaced, not appended twice
    text = report.read_text()
    assert "kept text" in text and text.count("## Texture recovery") == 1
    assert "| Ours (default preset) |" in text and "| NextFace* | not run" in text
    # A row whose cached fits used another configuration is not reported as if it were current.
    stale_nextface = out / "nextface" / "one" / "scores.json"
    stale = json.loads(stale_nextface.read_text())
    stale["config"]["seed"] += 1
    stale_nextface.write_text(json.dumps(stale))
    section = report_markdown(out, tmp_path / "pairs", "smoke", "deface bench run ...")
    assert "| NextFace | not run with the current configuration" in section
    assert "| Ours (default preset) | not run" not in section
