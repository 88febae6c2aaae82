"""The ``parknss`` command line: one typer app, every job a subcommand.

Command groups live in :mod:`parknss.commands`, one module each, registering themselves on
the app. User errors (:class:`~parknss.errors.ParknssError`) print one line on stderr and
exit with status 2, and so does an ``OSError`` a user can cause (a file without read
permission, an unwritable or full disk: :func:`os_error_line`); tables go to stdout, or
one JSON document with ``--json``.

SIGINT (Ctrl-C) exits 130 and SIGTERM 143, each with one line on stderr,
``parknss: interrupted: <what was kept; how to resume>`` (``terminated`` for SIGTERM):
the writers the interrupt unwinds through say what they kept
(:func:`parknss.outputs.interrupt_note`); pool workers are stopped with the command
(:func:`parknss.executor.run_jobs`).
"""

from __future__ import annotations

import contextlib
import importlib
import signal
import sys
from collections.abc import Iterator

import typer

from parknss.errors import ParknssError, one_line, show_warnings_as_lines
from parknss.outputs import interrupt_note

app = typer.Typer(
    name="parknss",
    help="Identify a physics-informed NSS plant of a car at parking speeds, prove its "
    "fidelity, and park through it.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # plain click help: rendering it through rich costs ~0.1 s a call
)

# Modules in parknss.commands, each with register(app).
COMMAND_MODULES: tuple[str, ...] = (
    "identify",
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
    "fidelity",
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

show_warnings_as_lines()  # tolerated-input warnings: one line each, no source path

for _name in COMMAND_MODULES:
    importlib.import_module(f"parknss.commands.{_name}").register(app)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like SIGINT's KeyboardInterrupt so that every
    writer unwinds the same way (atomic files and folders tidied, notes recorded)."""


@contextlib.contextmanager
def _signals() -> Iterator[list[int]]:
    """While the body runs, SIGINT and SIGTERM raise (a) KeyboardInterrupt in the main
    thread and are recorded in the yielded list; the earlier handlers come back after."""
    received: list[int] = []

    def handler(signum: int, _frame: object) -> None:
        received.append(signum)
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()

    try:
        earlier = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread: leave signals alone
        earlier = {}
    try:
        yield received
    finally:
        for s, h in earlier.items():
            signal.signal(s, h)


def os_error_line(exc: OSError) -> str:
    """An ``OSError`` as the one line after ``parknss: error:``: the file and the reason
    (``runs/x/a.json: No space left on device``)."""
    reason = exc.strerror or one_line(exc)
    return f"{exc.filename}: {reason}" if exc.filename is not None else reason


def _interrupted(signum: int) -> int:
    word = "terminated" if signum == signal.SIGTERM else "interrupted"
    note = interrupt_note(clear=True) or "nothing was written; run the same command again"
    print(f"parknss: {word}: {note}", file=sys.stderr)
    return 128 + signum


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app, turning ParknssError (and a user's OSError) into one line
    and exit code 2, SIGINT into 130 and SIGTERM into 143 with one line each."""
    interrupt_note(clear=True)
    with _signals() as received:
        try:
            code = app(args=argv, standalone_mode=False)
        except ParknssError as exc:
            print(f"parknss: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return _interrupted(received[-1] if received else signal.SIGINT)
        except typer.Abort:
            print("parknss: aborted", file=sys.stderr)
            return 1
        except RecursionError:
            print("parknss: error: input nested too deeply to read", file=sys.stderr)
            return 2
        except OSError as exc:
            print(f"parknss: error: {os_error_line(exc)}", file=sys.stderr)
            return 2
        except Exception as exc:  # click usage errors carry their own exit code
            code = getattr(exc, "exit_code", None)
            if code is not None and hasattr(exc, "show"):
                exc.show()
                return int(code)
            raise
        if code == 130 or received:  # typer turns KeyboardInterrupt into exit code 130
            return _interrupted(received[-1] if received else signal.SIGINT)
    return code if isinstance(code, int) else 0


if __name__ == "__main__":
    sys.exit(main())
