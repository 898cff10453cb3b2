"""`deface eval pairs DIR -o OUT`: the texture-swap protocol on a folder of source/target pairs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from deface.cli import options
from deface.fit import user_options
from deface.fit.log import console


def register(app: typer.Typer) -> None:
    eval_app = typer.Typer(no_args_is_help=True, help="Evaluate texture recovery (texture-swap protocol).")
    eval_app.command("pairs", epilog=options.settings_help())(pairs_command)
    app.add_typer(eval_app, name="eval")


def pairs_command(
    directory: Annotated[
        Path, typer.Argument(help="Folder of pairs: DIR/<name>/source.(png|jpg) + target.(png|jpg).")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="Where metrics.json and index.html go.")],
    preset: options.Preset = None,
    config_file: options.ConfigFile = None,
    sets: options.Set = None,
    models: options.Models = None,
    iterations: options.Iterations = None,
    lights: options.Lights = None,
    bands: options.Bands = None,
    light_masks: options.LightMasks = None,
    face_region: options.FaceRegion = None,
    priors: options.Priors = None,
) -> None:
    """Fit every pair's source and target, swap textures, score, write OUT/metrics.json and OUT/index.html."""
    from deface.eval.pairs import read_pairs
    from deface.eval.protocol import evaluate_pair
    from deface.eval.report import write_index_html, write_metrics_json

    try:
        user_options.check_models_dir(models)
        config = user_options.fit_config(preset, config_file, sets, iterations=iterations, lights=lights, bands=bands,
                                    light_masks=light_masks, face_region=face_region, priors=priors)
        pairs = read_pairs(directory)
    except (ValueError, FileNotFoundError) as error:
        console.print(f"[red]error:[/red] {escape(str(error))}")
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
