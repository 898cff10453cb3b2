"""The server's life: Gradio made offline and kept inside the output folder, launched on the configured address,
stopped cleanly on Ctrl-C or SIGTERM (running fits are stopped by the pool and leave nothing half-written).

Gradio is imported only after :func:`offline_environment` has set its variables (some are read at import).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from deface.web.config import WebConfig

GRADIO_DIR = ".gradio"  # Gradio's uploads and the copies of the files it serves, inside OUT
CACHE_CLEANING = (3600, 86400)  # Gradio removes its copies older than a day, checking every hour
PAGE_CSS = """
.error-line { color: #b3261e; }
#status { min-height: 3em; }
#viewer canvas { outline: none; }
#photo img, #render img, #render-face img, #relit img, #relit-face img {
  width: 100%; height: 100%; object-fit: contain; }
"""


def offline_environment(output: Path) -> None:
    """Gradio and huggingface_hub without the network (no analytics, update checks, telemetry or share links;
    no Node server) and with their files under ``output``."""
    os.environ.update({
        "GRADIO_ANALYTICS_ENABLED": "False",
        "GRADIO_TEMP_DIR": str(Path(output).resolve() / GRADIO_DIR),
        "GRADIO_SHARE": "False",
        "GRADIO_SSR_MODE": "False",
        "HF_HUB_OFFLINE": "1",
        "HF_HUB_DISABLE_TELEMETRY": "1",
    })


def launch(config: WebConfig):
    """Start the app for ``config`` without blocking -> the :class:`deface.web.app.WebApp` (its ``blocks`` serve
    at ``http://host:port``)."""
    output = Path(config.output).resolve()
    output.mkdir(parents=True, exist_ok=True)
    offline_environment(output)
    from deface.web.app import WebApp  # after the environment: Gradio reads some of it at import

    app = WebApp(config)
    app.blocks.queue(default_concurrency_limit=1)
    app.blocks.delete_cache = CACHE_CLEANING
    try:
        app.blocks.launch(server_name=config.host, server_port=config.port, share=False, inbrowser=False,
                          prevent_thread_lock=True, quiet=True, max_file_size=int(config.max_file_mb * 1024 * 1024),
                          allowed_paths=[str(output)], ssr_mode=False, mcp_server=False, css=PAGE_CSS,
                          footer_links=["settings"])
    except BaseException:  # the port is taken, the address cannot be bound, an interrupt: no queue left behind
        app.service.close()
        raise
    return app


def serve(config: WebConfig, announce=print) -> None:
    """Run the app until Ctrl-C or SIGTERM (either one from the start: the stop is clean at any time)."""
    previous = signal.signal(signal.SIGTERM, _interrupt)
    app = None
    try:
        app = launch(config)
        announce(f"deface serve: http://{_shown_host(config.host)}:{config.port} (outputs in "
                 f"{Path(config.output).resolve()}; {app.service.workers} worker process(es)); Ctrl-C stops it")
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        announce("deface serve: stopping (running fits are stopped; their outputs are not written)")
    finally:
        signal.signal(signal.SIGTERM, previous)
        if app is not None:
            app.service.close()
            app.blocks.close()


def _interrupt(_signum, _frame) -> None:
    raise KeyboardInterrupt


def _shown_host(host: str) -> str:
    return "127.0.0.1" if host in ("0.0.0.0", "") else host
