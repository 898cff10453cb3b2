"""How often a reader following one photo's fit, from ``deface fit`` to the written files, enters each package.

    python scripts/call_walk.py PHOTO [--iterations N] [--walk]

The walk is the depth-first order of the fit's calls into deface, each function read once: its first call
(later calls of a function already read, and everything below them, are skipped, as a reader skips code they
know; so are imports). A package (``deface.fit``, ``deface.render``, ...) is *entered* when the walk steps into
one of its functions from another package's while none of its functions is on the stack (a call back up into a
running package is not a new entry). A step's *level* is the number of packages entered on its stack.

The *spine* is the walk's top three levels: the command (``deface.cli``), what it calls (the options, the batch)
and what the batch calls (loading, the fit, writing, the page). On the spine, the entries of consecutive steps
into one package count once. Below it are the libraries the stages call (render, losses, models, ...), entered
wherever a stage needs them; their entries are printed too, for reading. Prints each package's spine entries,
the spine in order, and, with ``--walk``, the whole walk. The fit runs a few iterations per stage (the walk does
not depend on their number).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[1] / "deface")
SPINE_LEVELS = 3
SKIP = "skip"


def package(filename: str) -> str | None:
    """``deface.<package>`` of a source file of deface (None outside it); a top-level module is its own."""
    if not filename.startswith(ROOT):
        return None
    return "deface." + Path(filename[len(ROOT) + 1:]).with_suffix("").parts[0]


class Walk:
    """The depth-first walk of first calls (the module docstring), as ``sys.setprofile``'s hook."""

    def __init__(self) -> None:
        self.read: set[tuple[str, int]] = set()
        self.stack: list[tuple[str, int] | str | None] = []  # per live frame: (package, level), SKIP or None
        self.skipping = 0  # frames below a function already read
        self.steps: list[tuple[int, int, str, str, bool]] = []  # (depth, level, package, function, entered)

    def __call__(self, frame, event, _arg) -> None:
        if event == "call":
            self._call(frame.f_code)
        elif event == "return" and self.stack:
            if self.stack.pop() == SKIP:
                self.skipping -= 1

    def _call(self, code) -> None:
        name = package(code.co_filename)
        key = (code.co_filename, code.co_firstlineno)
        if self.skipping or (name is not None and (key in self.read or code.co_name == "<module>")):
            self.stack.append(SKIP)
            self.skipping += 1
            return
        if name is None:
            self.stack.append(None)
            return
        self.read.add(key)
        live = [entry for entry in self.stack if isinstance(entry, tuple)]
        entered = not live or (live[-1][0] != name and name not in {p for p, _ in live})
        level = (live[-1][1] if live else 0) + entered
        self.steps.append((len(live), level, name, f"{Path(code.co_filename).name}:{code.co_qualname}", entered))
        self.stack.append((name, level))

    def spine(self) -> list[str]:
        """The packages entered on the spine, in order, consecutive entries into one package merged."""
        order: list[str] = []
        for _, level, name, _, entered in self.steps:
            if entered and level <= SPINE_LEVELS and (not order or order[-1] != name):
                order.append(name)
        return order

    def library_entries(self) -> Counter:
        return Counter(name for _, level, name, _, entered in self.steps if entered and level > SPINE_LEVELS)


def walk_fit(photo: str, iterations: int = 4) -> Walk:
    """The walk of ``deface fit PHOTO`` with ``iterations`` steps per stage (outputs in a temporary folder)."""
    from deface.cli.main import main as deface_main

    walk = Walk()
    arguments = sys.argv
    with tempfile.TemporaryDirectory() as out:
        steps = ",".join([str(iterations)] * 3)
        sys.argv = ["deface", "fit", photo, "-o", out, "--iterations", steps, "--quiet"]
        sys.setprofile(walk)
        try:
            deface_main()
        except SystemExit:
            pass
        finally:
            sys.setprofile(None)
            sys.argv = arguments
    return walk


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("photo")
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--walk", action="store_true", help="print the whole walk")
    args = parser.parse_args()
    walk = walk_fit(args.photo, args.iterations)
    if args.walk:
        for depth, level, _, function, entered in walk.steps:
            print(f"{level} {'  ' * depth}{'> ' if entered else ''}{function}")
    spine = walk.spine()
    print("spine:", " -> ".join(spine))
    print("spine entries per package:", ", ".join(f"{n} {c}" for n, c in Counter(spine).most_common()))
    print("below the spine (libraries the stages call):",
          ", ".join(f"{n} {c}" for n, c in walk.library_entries().most_common()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
