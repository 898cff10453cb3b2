"""`deface bench`: benchmark data; `deface bench make-shadows` casts synthetic foreign shadows on photos."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from deface.paths import shared_dir

# The reference benchmark: clean single-face photos of ../shared/data/images (choice and reasons in
# docs/evaluation.md). Used when make-shadows is given no PHOTOS.
REFERENCE_PHOTOS = (
    "000031.jpg", "015270.jpg", "IMG_0392_inputs.jpg", "JianzhuGuo.jpg", "image02202.jpg",
    "nextface-s1.png", "nextface-s2.png", "nextface-s3.png", "nextface-s5.png", "nextface-s6.png",
    "nextface-s7.png", "psm-clean-006.png", "psm-clean-008.png", "vd006.png", "vd092.png", "vd102.png",
)


def register(app: typer.Typer) -> None:
    bench = typer.Typer(
        no_args_is_help=True, help="Benchmark data (synthetic shadow pairs) and the texture-recovery benchmark."
    )
    bench.command("make-shadows")(make_shadows_command)
    bench.command("run")(run_command)
    bench.command("skin-tone")(skin_tone_command)
    bench.command("sheet")(sheet_command)
    bench.command("albedo")(albedo_command)
    bench.command("board")(board_command)
    app.add_typer(bench, name="bench")


def _reference_photos() -> list[Path]:
    shared = shared_dir()
    if shared is None:
        raise typer.BadParameter("no PHOTOS given and ../shared is absent (set DEFACE_SHARED or pass photos)")
    return [shared / "data" / "images" / name for name in REFERENCE_PHOTOS]


def make_shadows_command(
    output: Annotated[Path, typer.Option("-o", "--output", help="Benchmark folder to write.")],
    photos: Annotated[
        list[Path] | None, typer.Argument(help="Clean face photos; default: the reference set in ../shared.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives identical files.")] = 0,
    per_photo: Annotated[int, typer.Option("--per-photo", help="Shadowed variants per photo.")] = 1,
    max_size: Annotated[int, typer.Option("--max-size", help="Shrink to this longest side.")] = 512,
    silhouettes: Annotated[
        Path | None,
        typer.Option(help="Folder of silhouette PNGs; default ../shared/data/shadow-silhouettes."),
    ] = None,
    mediapipe: Annotated[bool, typer.Option(help="Find the face with MediaPipe.")] = True,
    kinds: Annotated[str | None, typer.Option(
        help="Comma list of occluder kinds (default: silhouette,hat,leaves,fingers,blinds; also stripes, dapples).")
    ] = None,
    fill: Annotated[str, typer.Option(help="R,G,B colour of the light left in the shadow (a cool sky: "
                                           "0.55,0.75,1).")] = "1,1,1",
    warm: Annotated[str, typer.Option(help="MIN,MAX warmth of the key light on the whole photo (0: none).")] = "0,0",
    penumbra: Annotated[str, typer.Option(help="MIN,MAX penumbra sigma, fraction of the face's size (sunlight: "
                                               "0.002,0.01).")] = "0.004,0.035",
) -> None:
    """Write OUTPUT/<photo>-<k>/{source,target,shadow_mask}.png and OUTPUT/manifest.json."""
    from rich.console import Console

    from deface.eval.shadows import (
        EXTRA_KINDS,
        SHAPE_KINDS,
        ShadowConfig,
        make_shadow_benchmark,
        shared_silhouettes,
        silhouette_files,
    )

    photos = list(photos) if photos else _reference_photos()
    missing = [str(p) for p in photos if not Path(p).is_file()]
    if missing:
        raise typer.BadParameter(f"photo(s) not found: {', '.join(missing)}")
    folder = silhouettes or shared_silhouettes()
    if silhouettes is not None and not silhouettes.is_dir():
        raise typer.BadParameter(f"--silhouettes {silhouettes} is not a folder")
    files = silhouette_files(folder)
    chosen = tuple(k.strip() for k in kinds.split(",") if k.strip()) if kinds else SHAPE_KINDS
    unknown = [k for k in chosen if k not in SHAPE_KINDS + EXTRA_KINDS]
    if unknown:
        raise typer.BadParameter(f"--kinds: unknown {', '.join(unknown)}; choose from "
                                 f"{', '.join(SHAPE_KINDS + EXTRA_KINDS)}")
    chosen = chosen if files else tuple(k for k in chosen if k != "silhouette")
    if not chosen:
        raise typer.BadParameter("--kinds: silhouette needs silhouette files, and none were found")
    config = ShadowConfig(kinds=chosen, silhouettes=files, fill=_floats(fill, 3, "--fill"),
                          warm=_floats(warm, 2, "--warm"), penumbra=_floats(penumbra, 2, "--penumbra"))
    manifest = make_shadow_benchmark(
        photos, output, seed=seed, per_photo=per_photo, max_size=max_size, use_mediapipe=mediapipe,
        config=config,
    )
    console = Console()
    for pair in manifest["pairs"]:
        console.print(
            f"{pair['name']}: {pair['kind']:<10} coverage {pair['coverage']:.2f} keep {pair['keep']:.2f} "
            f"face {pair['face_region']}"
        )
    console.print(f"wrote {len(manifest['pairs'])} pairs to {output}")


def _floats(text: str, count: int, name: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != count or any(v < 0 for v in values):
        raise typer.BadParameter(f"{name}: need {count} comma-separated non-negative numbers, got {text!r}")
    return values


def run_command(
    pairs: Annotated[Path, typer.Argument(help="Pairs folder (from make-shadows).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Results folder (cached per pair).")],
    variants: Annotated[str, typer.Option(help="Comma list of variants in priority order, or 'all'.")] = "all",
    schedule: Annotated[str, typer.Option(help="'quick' (recorded tables) or 'full' (presets as defined).")] = "quick",
    jobs: Annotated[int, typer.Option(help="Fits in parallel (one per core).")] = 2,
    limit: Annotated[int | None, typer.Option(help="Use only the first N pairs (sorted by name).")] = None,
    report: Annotated[Path, typer.Option(help="Markdown file whose evaluation section is rewritten.")] = Path(
        "BENCHMARKS.md"),
) -> None:
    """Fit every variant on every pair (texture-swap protocol), then rewrite the tables in REPORT."""
    from deface.eval.benchmark import VARIANTS, report_markdown, run_benchmark, update_benchmarks_md

    console = _console()
    names = list(VARIANTS) if variants == "all" else [v.strip() for v in variants.split(",") if v.strip()]
    _checked_schedule(schedule)
    with _usage_errors(console):
        run_benchmark(pairs, output, names, schedule, jobs, limit, log=console.print)
    command = f"deface bench run {pairs} -o {output} --variants {variants} --schedule {schedule} --jobs {jobs}"
    command += f" --limit {limit}" if limit else ""
    update_benchmarks_md(report, report_markdown(output, pairs, schedule, command, limit))
    console.print(f"wrote the evaluation tables to {report}")


def sheet_command(
    results: Annotated[Path, typer.Argument(help="Results folder of `deface bench run`.")],
    pairs: Annotated[str, typer.Option(help="Comma list of pair names to show.")],
    variants: Annotated[str, typer.Option(help="Comma list of variants (columns).")] = "ours,nextface",
    before: Annotated[Path | None, typer.Option(help="An earlier results folder: its first variant's map too.")] = None,
) -> None:
    """RESULTS/textures_sheet.png: the photos and the diffuse maps fitted from each, per pair and variant."""
    from deface.eval.sheets import texture_sheet

    names = [p.strip() for p in pairs.split(",") if p.strip()]
    chosen = [v.strip() for v in variants.split(",") if v.strip()]
    missing = [f"{v}/{p}" for v in chosen for p in names if not (results / v / p / "source.png").is_file()]
    if missing:
        typer.echo(f"error: no results for {', '.join(missing)} in {results}", err=True)
        raise typer.Exit(2)
    typer.echo(f"wrote {texture_sheet(results, names, chosen, before)}")


def skin_tone_command(
    folder: Annotated[Path, typer.Argument(help="Folder with images/ and MANIFEST.tsv (file, tone_group[, gt_ita][, "
                                                "settings: a photo's own PATH=VALUE;...]).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Results folder (fits cached per photo).")],
    preset: Annotated[str, typer.Option(help="The preset measured.")] = "default",
    baseline: Annotated[bool, typer.Option("--baseline/--no-baseline", help="Also fit NextFace.")] = True,
    schedule: Annotated[str, typer.Option(help="'full' (presets as defined) or 'quick'.")] = "full",
    jobs: Annotated[int, typer.Option(help="Fits in parallel (one per core).")] = 2,
    models: Annotated[Path | None, typer.Option("--models", help="Model files folder.")] = None,
    report: Annotated[Path | None, typer.Option(help="Also rewrite this dataset's section of this file.")] = None,
) -> None:
    """ITA of each recovered albedo against the photo's (or the true) skin tone; report.md, results.json and
    contact_sheet.png in OUTPUT."""
    from deface.eval.tone_benchmark import (
        contact_sheet,
        read_manifest,
        report_markdown,
        run_tone_benchmark,
        summary,
        summary_line,
        with_proxy,
    )
    from deface.fit import presets

    console = _console()
    steps = _checked_schedule(schedule)
    with _usage_errors(console):
        presets.get(preset)
        photos = read_manifest(folder)
    records = run_tone_benchmark(folder, output, preset, baseline, steps, jobs, models, log=console.print)
    command = f"deface bench skin-tone {folder} -o {output} --preset {preset} --schedule {schedule}"
    command += "" if baseline else " --no-baseline"
    scored = with_proxy(photos, records)
    summaries = {variant: summary(photos, recs) for variant, recs in scored.items()}
    results = {variant: {"summary": summaries[variant], "photos": recs} for variant, recs in scored.items()}
    section = report_markdown(photos, records, folder.resolve().name, command)
    _write_set_results(console, folder, output, "skin-tone", section, results,
                       contact_sheet(folder, output, photos, list(records)), report,
                       [summary_line(variant, s) for variant, s in summaries.items()])


def albedo_command(
    folder: Annotated[Path, typer.Argument(help="Truth set: images/, albedo/, MANIFEST.tsv[, masks/, mesh.obj].")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Results folder (fits cached per render).")],
    presets_: Annotated[str, typer.Option("--preset", help="Comma list of presets measured.")] = "default",
    settings: Annotated[list[str] | None, typer.Option("--set", help="PATH=VALUE config change for every "
                                                       "preset (as deface fit --set); names the variant.")] = None,
    schedule: Annotated[str, typer.Option(help="'full' (presets as defined) or 'quick'.")] = "full",
    jobs: Annotated[int, typer.Option(help="Fits in parallel (one per core).")] = 2,
    models: Annotated[Path | None, typer.Option("--models", help="Model files folder.")] = None,
    report: Annotated[Path | None, typer.Option(help="Also rewrite this set's section of this file.")] = None,
    sets: Annotated[bool, typer.Option("--sets", help="Also fit each set of renders of one albedo (the manifest's "
                                       "'set' column; else all of one albedo) as several photos of one person, "
                                       "scored beside its photos alone: sets.md, sets.json.")] = False,
) -> None:
    """Fit renders of known albedo and score each diffuse map against the truth in UV: PSNR, SSIM, colour noise,
    colour error, and per region (the set's masks) the darkness kept and the fine structure; report.md,
    results.json and contact_sheet.png in OUTPUT."""
    from deface.eval.albedo_benchmark import (
        contact_sheet,
        read_truth_set,
        report_markdown,
        run_albedo_benchmark,
        summary,
        summary_line,
    )
    from deface.fit import presets
    from deface.fit.config import override, set_from_text

    console = _console()
    steps = _checked_schedule(schedule)

    def configured(name: str):
        config = override(presets.get(name), **steps)
        for assignment in settings or []:
            config = set_from_text(config, assignment)
        return config

    suffix = "+" + ",".join(settings) if settings else ""
    with _usage_errors(console):
        renders = read_truth_set(folder)
        variants = {f"{name}{suffix}": configured(name)
                    for name in (p.strip() for p in presets_.split(",") if p.strip())}
    records = run_albedo_benchmark(folder, output, variants, jobs, models, log=console.print)
    command = f"deface bench albedo {folder} -o {output} --preset {presets_} --schedule {schedule}"
    command += "".join(f" --set {s}" for s in settings or [])
    summaries = {variant: summary(recs) for variant, recs in records.items()}
    results = {variant: {"summary": summaries[variant], "renders": recs} for variant, recs in records.items()}
    section = report_markdown(renders, records, folder.resolve().name, command)
    _write_set_results(console, folder, output, "albedo", section, results,
                       contact_sheet(folder, output, renders, list(records)), report,
                       [summary_line(variant, s) for variant, s in summaries.items()])
    if sets:
        from deface.eval.person_benchmark import run_person_benchmark, sets_markdown

        set_records = run_person_benchmark(folder, output, variants, records, jobs, models, log=console.print)
        (output / "sets.md").write_text(sets_markdown(set_records, folder.resolve().name, command + " --sets"))
        (output / "sets.json").write_text(json.dumps(set_records, indent=1))
        console.print(f"sets: {output / 'sets.md'}")


def board_command(
    output: Annotated[Path, typer.Option("-o", "--output", help="Results folder (pairs and fits, cached per fit).")],
    preset: Annotated[str, typer.Option(help="The preset judged (default: the shipped default).")] = "default",
    settings: Annotated[list[str] | None, typer.Option("--set", help="PATH=VALUE change judged (as deface fit "
                                                       "--set).")] = None,
    only: Annotated[str | None, typer.Option(help="Comma list of splits (default: all but the held-out one).")] = None,
    held_out: Annotated[bool, typer.Option("--held-out", help="Also the split no choice has seen.")] = False,
    jobs: Annotated[int, typer.Option(help="Fits in parallel (one per core).")] = 2,
    models: Annotated[Path | None, typer.Option("--models", help="Model files folder.")] = None,
    accept: Annotated[bool, typer.Option(help="Record these figures as the accepted default's "
                                              "(benchmarks/board/accepted.json).")] = False,
) -> None:
    """Judge a configuration on every board split (fresh shadow pairs, truth renders) against the last accepted
    default: one table, a LOSS where a figure is worse beyond its seed noise; exit 1 if any."""
    import json
    import time

    from deface.eval.board import ACCEPTED, compare, read_accepted, run_board, split_names, table_markdown
    from deface.fit import presets
    from deface.fit.config import set_from_text

    console = _console()
    with _usage_errors(console):
        config = presets.get(preset)
        for assignment in settings or []:
            config = set_from_text(config, assignment)
        names = [n.strip() for n in only.split(",") if n.strip()] if only else split_names(held_out)
        figures = run_board(config, output, names, jobs, models, log=console.print)
    rows = compare(figures, read_accepted()["figures"])
    command = "deface bench board -o OUT" + (f" --preset {preset}" if preset != "default" else "")
    command += "".join(f" --set {s}" for s in settings or []) + (f" --only {only}" if only else "")
    command += " --held-out" if held_out else ""
    table = table_markdown(rows)
    (output / "board.md").write_text(f"`{command}` ({time.strftime('%Y-%m-%d')})\n\n{table}")
    (output / "board.json").write_text(json.dumps({"command": command, "figures": figures}, indent=1) + "\n")
    console.print(table, markup=False, highlight=False)
    if accept:
        accepted = read_accepted()
        accepted["figures"].update(figures)
        accepted["command"], accepted["date"] = command, time.strftime("%Y-%m-%d")
        ACCEPTED.write_text(json.dumps(accepted, indent=1) + "\n")
        console.print(f"recorded as the accepted default's figures in {ACCEPTED}")
    losses = [r for r in rows if r["loss"]]
    if losses:
        console.print(f"{len(losses)} figure(s) lost beyond the noise: " +
                      ", ".join(f"{r['split']} {r['measure']}" for r in losses))
        raise typer.Exit(1)


def _console():
    from rich.console import Console

    return Console(soft_wrap=True)


def _checked_schedule(schedule: str) -> dict:
    """The settings of a named schedule (deface/eval/benchmark.py ``SCHEDULES``); a usage error for another name."""
    from deface.eval.benchmark import SCHEDULES

    if schedule not in SCHEDULES:
        raise typer.BadParameter(f"unknown schedule {schedule!r}; choose {', '.join(SCHEDULES)}")
    return SCHEDULES[schedule]


@contextmanager
def _usage_errors(console) -> Iterator[None]:
    """A ValueError (an unknown variant or preset, a set that cannot be read) is one red line and exit code 2."""
    try:
        yield
    except ValueError as error:
        console.print(f"[red]error:[/red] {error}")
        raise typer.Exit(2) from None


def _write_set_results(console, folder: Path, output: Path, kind: str, section: str, results: dict, sheet: Path,
                       report: Path | None, lines: list[str]) -> None:
    """OUTPUT/report.md and results.json of a truth or photo set's benchmark, its section ``KIND-<set>`` of REPORT
    when given, then one line per variant and where the files are (the contact sheet is written already)."""
    from deface.eval.benchmark import update_benchmarks_md

    (output / "report.md").write_text(section)
    (output / "results.json").write_text(json.dumps(results, indent=1))
    if report is not None:
        update_benchmarks_md(report, section, key=f"{kind}-{folder.resolve().name}")
    for line in lines:
        console.print(line)
    console.print(f"wrote {output / 'report.md'} and {sheet}")
