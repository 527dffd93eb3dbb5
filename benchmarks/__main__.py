"""Run the benchmarks and write BENCHMARKS.md into a folder: ``python -m benchmarks [--only core design env
conditioning] [--quick] [--out FOLDER]`` (``--out .`` rewrites the committed BENCHMARKS.md)."""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import sys
from pathlib import Path

from formation_env._progress import add_progress_argument, progress_bar

from .timing import machine

#: Benchmark modules in report order; a module whose optional dependencies are missing is reported as skipped.
MODULES = {
    "core": "benchmarks.core_bench",
    "design": "benchmarks.design_bench",
    "env": "benchmarks.env_bench",
    "conditioning": "benchmarks.conditioning",
}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    p.add_argument("--only", nargs="*", choices=sorted(MODULES), help="run only these sections")
    p.add_argument("--quick", action="store_true", help="fewer repeats")
    p.add_argument("--out", default="out", help="folder of the BENCHMARKS.md written (default out)")
    add_progress_argument(p)
    args = p.parse_args(argv)
    names = args.only or list(MODULES)
    out = Path(args.out)
    if out.suffix == ".md":
        p.error(f"--out is a folder (BENCHMARKS.md is written inside it), got the file name {args.out!r}")
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    parts = [
        "# Benchmarks",
        "",
        f"Measured {stamp} on {machine()} by `python -m benchmarks"
        + (f" --only {' '.join(names)}" if args.only else "")
        + (" --quick" if args.quick else "")
        + "`. Rerun it to check; medians over repeats, min-max beside them.",
        "",
    ]
    bar = progress_bar(len(names), "bench", args.progress, "section")
    for name in names:
        bar.set_description_str(f"bench: {name}")
        try:
            mod = importlib.import_module(MODULES[name])
        except ImportError as exc:
            parts += [f"## {name}", "", f"Skipped: {exc}", ""]
            print(f"[{name}] skipped: {exc}", file=sys.stderr)
            bar.update()
            continue
        print(f"[{name}] {mod.TITLE} ...", file=sys.stderr, flush=True)
        rows = mod.run(quick=args.quick)
        table = mod.markdown(rows)
        print(table)
        parts += [f"## {mod.TITLE}", "", (mod.__doc__ or "").strip(), "", table, ""]
        bar.update()
    bar.close()
    out.mkdir(parents=True, exist_ok=True)
    path = out / "BENCHMARKS.md"
    path.write_text("\n".join(parts))
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
