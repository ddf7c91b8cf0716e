"""The `eoloc` command group and its consoles: a user's mistake becomes one message and exit code
2, a bug keeps its traceback. Command modules never import this module's group: they define plain
click commands that ``eoloc.cli`` registers, so no command module sits in an import circle."""

from __future__ import annotations

import os
import sys

import click
from rich.console import Console
from rich.markup import escape

from .. import __version__
from ..errors import EolocError
from .options import CONVENTIONS, negative_values_kept
from .render import print_issues

#: Off a terminal (a pipe, a file, CI) rich would wrap and cut at 80 columns: cells cut to "statu",
#: file names over three lines. There, lines are as long as they need to be (COLUMNS still rules).
WIDTH_OFF_TERMINAL = 1000


def make_console(stderr: bool = False) -> Console:
    """A console for stdout or stderr: the terminal's width on a terminal, else unwrapped lines."""
    c = Console(stderr=stderr)
    if c.is_terminal or os.environ.get("COLUMNS"):
        return c
    return Console(stderr=stderr, width=WIDTH_OFF_TERMINAL)


console = make_console()
err_console = make_console(stderr=True)


def fail(message: str) -> None:
    """A usage mistake found by a command itself: one line on stderr, exit code 2."""
    # messages name config sections ([accuracy]): escaped; one line, never wrapped, so paths stay whole
    err_console.print(f"[bold red]error:[/] {escape(message)}", soft_wrap=True)
    sys.exit(2)


#: The exit status of a run that wrote its outputs but located nothing at all (CONVENTIONS).
NOTHING_LOCATED = 3


def exit_if_nothing_located(fixes) -> None:
    """Exit with :data:`NOTHING_LOCATED` when there were targets and none was located: a script
    must not take an all-failed run for a good one (the warning before says why)."""
    from ..jobs.explain import nothing_located

    if nothing_located(fixes):
        sys.exit(NOTHING_LOCATED)


def report_issues(issues, limit: int = 15) -> None:
    """The per-line problems of the inputs (file:line: message), the first ``limit`` of them."""
    print_issues(issues, err_console, limit)


def warn(message: str, label: str = "warning") -> None:
    err_console.print(f"[yellow]{label}:[/] {escape(message)}", highlight=False, soft_wrap=True)


class Main(click.Group):
    """The command group: a user's mistake (an EolocError: a file or configuration that cannot be
    used; an OSError: a path that cannot be read or written; an optional part of eoloc the command
    needs and the install lacks) becomes a message and exit code 2; anything else is a bug in eoloc
    and keeps its traceback, with a line asking to report it."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.lazy: dict[str, tuple[str, str]] = {}  # command -> (module, object), imported on first use

    def add_lazy_command(self, name: str, module: str, attr: str) -> None:
        """Register command ``name`` as ``module.attr``, imported only when it is run or listed."""
        self.lazy[name] = (module, attr)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*self.commands, *self.lazy})

    def get_command(self, ctx: click.Context, name: str):
        if name not in self.commands and name in self.lazy:
            from importlib import import_module

            module, attr = self.lazy[name]
            self.add_command(getattr(import_module(module), attr), name)
        return super().get_command(ctx, name)

    def main(self, args=None, *rest, **kwargs):
        args = sys.argv[1:] if args is None else list(args)
        return super().main(negative_values_kept(args), *rest, **kwargs)

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except EolocError as exc:
            report_issues(exc.issues)
            fail(str(exc))
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            fail(f"{where}{exc.strerror or exc}")
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except ModuleNotFoundError as exc:
            from ..util.extras import missing_extra

            missing = missing_extra(exc)
            if missing is None:
                raise
            fail(str(missing))
        except Exception:
            err_console.print("[bold red]internal error:[/] this is a bug in eoloc, not in your input. Please report "
                              "it with the command line and the traceback below.")
            raise


@click.group(cls=Main, help="eoloc - geolocate ground targets seen by airborne electro-optical sensors.\n"
             + CONVENTIONS)
@click.version_option(__version__, prog_name="eoloc")
def main() -> None:
    pass
