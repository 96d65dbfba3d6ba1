"""The ``clothsim`` command line: simulate, render, info and benchmarks."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from typing import NoReturn

from ..version import __version__
from ..errors import ClothsimError

EPILOG = """\
scenes: a path to a course scene file (JSON with cloth/sphere/plane), or the bare name (no / and
no .json) of a bundled scene: pinned2, pinned4, sphere, plane, selfCollision (the course's), flag,
shake, capsule, curtain, tablecloth, mesh, heap, push, breathing, skirt, cape, drum.

examples:
  clothsim simulate scenes/sphere.json --frames 180 --out sphere.npz
  clothsim render sphere --shader phong -o sphere.png
  clothsim export sphere --frames 180 -o sphere.usd   # or -o sphere_obj/ for an OBJ sequence
  clothsim sweep selfCollision --set cloth.density=1,15,1000 --set cloth.ks=10,5000,200000 -o sheet.png
  clothsim serve sphere            # the interactive GUI in a browser (prints the URL to open)
  clothsim check-intersections sphere.npz   # does the cloth pass through itself?
  clothsim bench speed
  clothsim compile                 # compile every kernel now (images, CI caches, cluster workers)
"""


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    print(f"clothsim: warning: {message}", file=sys.stderr)


class _Parser(argparse.ArgumentParser):
    """A parser whose usage errors are one line, like every other error (subcommands inherit it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"clothsim: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, with every subcommand registered."""
    parser = _Parser(
        prog="clothsim",
        description="Simulate and render mass-spring cloth from CS184-style scene files.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"clothsim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    from ..commands import add_simulate_parser

    add_simulate_parser(sub)

    from ..exporters.commands import add_parser as add_export_parser

    add_export_parser(sub)

    from ..sweeps.commands import add_parser as add_sweep_parser

    add_sweep_parser(sub)

    from ..serve.command import add_parser as add_serve_parser

    add_serve_parser(sub)

    from .crossings import add_parser as add_crossings_parser

    add_crossings_parser(sub)
    bench = sub.add_parser("bench", help="benchmarks: speed, render, accuracy, stability, scaling, sweep, colliders, serve, selfcollision, "
                           "passes",
                           description="Benchmarks that print figures measured on this machine.")
    bench_sub = bench.add_subparsers(dest="bench_command", metavar="BENCHMARK")
    bench.set_defaults(func=lambda args: (bench.print_help(), 2)[1])

    from . import compile as compiling
    from ..bench import accuracy, scaling, speed, stability
    from ..bench import colliders as bench_colliders
    from ..bench import compile as bench_compile
    from ..bench import passes as bench_passes
    from ..bench import selfcollision as bench_selfcollision
    from ..bench import serve as bench_serve
    from ..bench import sweep as bench_sweep
    from .render import add_parsers as add_render_parsers

    speed.add_parser(bench_sub)
    add_render_parsers(sub, bench_sub)
    for module in (accuracy, stability, scaling, bench_compile, bench_sweep, bench_serve, bench_colliders,
                   bench_selfcollision, bench_passes):
        module.add_parser(bench_sub)
    compiling.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code (2 for bad input, with a one-line message)."""
    warnings.showwarning = _show_warning
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    if getattr(args, "kernels", True):  # a command that runs no kernel here does not load Numba
        from ..jit.watch import install_notice

        install_notice()
    try:
        return int(args.func(args) or 0)
    except ClothsimError as exc:
        print(f"clothsim: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("clothsim: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("clothsim: error: out of memory", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
