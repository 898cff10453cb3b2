"""deface's web app as a hosted demo: what a Hugging Face Space (SDK gradio) runs as ``python app.py``, or anyone
with ``python app.py`` on their own machine. The same app as `deface serve`, with settings for a shared CPU machine:
one fit at a time, the fast preset first, small uploads, and only the newest jobs kept on disk. docs/web.md says how
to set up a Space (the model files, the requirements).

Environment: ``DEFACE_MODELS`` (else ``./models`` beside this file when present, else the user's cache), the output
folder ``DEFACE_WEB_OUTPUT`` (default ``./deface-web``), and Gradio's ``GRADIO_SERVER_NAME`` / ``GRADIO_SERVER_PORT``
(a Space sets ``SPACE_ID`` and needs 0.0.0.0:7860; elsewhere it listens on localhost only).
"""

from __future__ import annotations

import os
from pathlib import Path

HERE = Path(__file__).resolve().parent


def hosted_config():
    from deface.web.config import WebConfig

    models = HERE / "models" if not os.environ.get("DEFACE_MODELS") and (HERE / "models").is_dir() else None
    on_space = bool(os.environ.get("SPACE_ID"))
    return WebConfig(
        output=Path(os.environ.get("DEFACE_WEB_OUTPUT", HERE / "deface-web")),
        host=os.environ.get("GRADIO_SERVER_NAME") or ("0.0.0.0" if on_space else "127.0.0.1"),
        port=int(os.environ.get("GRADIO_SERVER_PORT", "7860")),
        models=models,
        workers=1,  # a shared CPU: one fit at a time, the others wait in turn and are told so
        presets=("fast", "default", "paper", "nextface"),
        max_file_mb=20.0,
        max_files=4,
        keep_jobs=50,
    )


def main() -> None:
    from deface.web.serve import serve

    config = hosted_config()
    config.check()
    serve(config)


if __name__ == "__main__":  # the fits' worker processes import this file again: nothing may start on import
    main()
