"""The ``parknss`` command line: one typer app, every job a subcommand.

Command groups live in :mod:`parknss.commands`, one module each, registering themselves on
the app. User errors (:class:`~parknss.errors.ParknssError`) print one line on stderr and
exit with status 2; tables go to stdout, or one JSON document with ``--json``.
"""

from __future__ import annotations

import importlib
import sys

import typer

from parknss.errors import ParknssError

app = typer.Typer(
    name="parknss",
    help="Identify a physics-informed NSS plant of a car at parking speeds, prove its "
    "fidelity, and park through it.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

# Modules in parknss.commands, each with register(app).
COMMAND_MODULES: tuple[str, ...] = (
    "campaign",
    "demo",
    "reproduce",
    "plan",
    "rate",
    "simulate",
    "actuators",
    "web",
    "nss",
    "study",
    "results",
    "export",
)

def _version(value: bool) -> None:
    if value:
        from parknss import __version__

        typer.echo(f"parknss {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Identify a physics-informed NSS plant of a car at parking speeds, prove its
    fidelity, and park through it."""


for _name in COMMAND_MODULES:
    importlib.import_module(f"parknss.commands.{_name}").register(app)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app, turning ParknssError into one line and exit code 2."""
    try:
        app(args=argv, standalone_mode=False)
    except ParknssError as exc:
        print(f"parknss: error: {exc}", file=sys.stderr)
        return 2
    except typer.Abort:
        print("parknss: aborted", file=sys.stderr)
        return 1
    except Exception as exc:  # click usage errors carry their own exit code
        code = getattr(exc, "exit_code", None)
        if code is not None and hasattr(exc, "show"):
            exc.show()
            return int(code)
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main())
