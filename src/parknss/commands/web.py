"""``parknss web``: serve the interactive closed-loop simulator in the browser.

Starts the FastAPI app of :mod:`parknss.web.app` with uvicorn on ``--host``/``--port``
(defaults from configs/web.yaml) and, with ``--open``, opens the page in the default
browser once the server is up. Stop it with Ctrl-C. Off loopback it warns and requires
an access token (``--token`` or ``PARKNSS_WEB_TOKEN``); see docs/web.md, "The network".
"""

from __future__ import annotations

import threading
import webbrowser
from pathlib import Path

import typer


def _log(msg: str) -> None:
    typer.echo(f"[web] {msg}", err=True)


def register(app: typer.Typer) -> None:
    @app.command("web", short_help="Serve the parking simulator in the browser.")
    def web(
        host: str | None = typer.Option(None, "--host", help="Bind address (web.yaml: 127.0.0.1)."),
        port: int | None = typer.Option(None, "--port", help="TCP port (web.yaml: 8000)."),
        open_browser: bool = typer.Option(
            True, "--open/--no-open", help="Open the page in the default browser."
        ),
        config: Path | None = typer.Option(None, "--config", help="Web YAML (configs/web.yaml)."),
        vehicle: Path | None = typer.Option(
            None, "--vehicle", help="Vehicle YAML (web.yaml: the chain's car)."
        ),
        token: str | None = typer.Option(
            None,
            "--token",
            envvar="PARKNSS_WEB_TOKEN",
            show_envvar=True,
            help="Access token every request must carry (required off loopback).",
        ),
    ) -> None:
        """Serve the interactive parking simulator (plan, run, play back) in the browser."""
        import uvicorn

        from parknss.web.app import create_app
        from parknss.web.config import load_web_config
        from parknss.web.guard import exposure_warning

        given = (
            ("host", host),
            ("port", port),
            ("vehicle", vehicle and str(vehicle)),
            ("token", token),
        )
        overrides = {k: v for k, v in given if v is not None}
        cfg = load_web_config(config, **overrides)
        warning = exposure_warning(cfg.host, cfg.token)
        if warning:
            _log(warning)
        shown = f"[{cfg.host}]" if ":" in cfg.host else cfg.host
        url = f"http://{shown}:{cfg.port}/"
        server = uvicorn.Server(
            uvicorn.Config(create_app(cfg), host=cfg.host, port=cfg.port, log_level="warning")
        )
        if open_browser:

            def _open_when_up() -> None:
                while not server.started and not server.should_exit:
                    threading.Event().wait(0.1)
                if server.started:
                    webbrowser.open(url + (f"?token={cfg.token}" if cfg.token else ""))

            threading.Thread(target=_open_when_up, daemon=True).start()
        _log(f"serving the simulator at {url} (Ctrl-C stops it)")
        server.run()
