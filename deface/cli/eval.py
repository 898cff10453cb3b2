"""`deface eval pairs DIR -o OUT`: the texture-swap protocol on a folder of source/target pairs."""

from __future__ import annotations

from pathlib import Path

import typer

from deface.fit import presets
from deface.fit.log import console


def register(app: typer.Typer) -> None:
    eval_app = typer.Typer(no_args_is_help=True, help="Evaluate texture recovery (texture-swap protocol).")
    eval_app.command("pairs")(pairs_command)
    app.add_typer(eval_app, name="eval")


def pairs_command(
    directory: Path = typer.Argument(..., help="Folder of pairs: DIR/<name>/source.(png|jpg) + target.(png|jpg)."),
    output: Path = typer.Option(..., "-o", "--output", help="Where metrics.json and index.html go."),
    preset: str = typer.Option("default", help=f"One of: {', '.join(presets.names())}."),
    models: Path | None = typer.Option(None, "--models", help="Model files folder."),
    iterations: str | None = typer.Option(None, help="Iterations per stage S1,S2,S3 (override the preset)."),
    lights: int | None = typer.Option(None, help="Ablation: n."),
    bands: int | None = typer.Option(None, help="Ablation: SH bands."),
    light_masks: bool | None = typer.Option(None, "--light-masks/--no-light-masks"),
    face_region: bool | None = typer.Option(None, "--face-region/--no-face-region"),
    priors: str | None = typer.Option(None, help="Ablation: gp,lp,hp or none."),
) -> None:
    """Fit every pair's source and target, swap textures, score, write OUT/metrics.json and OUT/index.html."""
    from deface.cli.fit import _config
    from deface.eval.pairs import read_pairs
    from deface.eval.protocol import evaluate_pair
    from deface.eval.report import write_index_html, write_metrics_json

    try:
        config = _config(preset, 0, lights, bands, light_masks, face_region, priors, None, iterations,
                         None, None, None)
        pairs = read_pairs(directory)
    except (ValueError, FileNotFoundError) as error:
        console.print(f"[red]error:[/red] {error}")
        raise typer.Exit(2) from None
    outcomes = []
    for index, pair in enumerate(pairs):
        console.print(f"[{index + 1}/{len(pairs)}] {pair.name}")
        outcome = evaluate_pair(pair, config, output / pair.name, models)
        outcomes.append(outcome)
        target = outcome.scores.target["face"]
        distance = outcome.scores.target.get("identity", {}).get("distance")
        identity = "" if distance is None else f", identity distance {distance:.3f}"
        console.print(f"  target synthesis (face): PSNR {target['psnr']:.2f} dB, SSIM {target['ssim']:.3f}, "
                      f"LPIPS {target['lpips']:.2f}{identity}; {outcome.seconds_per_fit:.0f} s per fit")
    write_metrics_json(output / "metrics.json", config.preset, [o.scores for o in outcomes])
    write_index_html(output / "index.html", [o.row for o in outcomes], title=f"deface eval: {config.preset}")
    console.print(f"wrote {output / 'metrics.json'} and {output / 'index.html'}")
