"""Reference counts the compiled kernels take per trace, by the function they return into.

    .venv/bin/python benchmarks/count_refcounts.py [--extract PATH] [--interval 15]
        [--fixes 25] [--traces 20] [--csv TRACES.csv --sigma 10] [--top 25]

numba counts references on an array (a call and an atomic add: ``NRT_incref`` /
``NRT_decref``) wherever an array variable's life ends at different places on different
paths, and on every array a helper is handed at its entry and exit when the pruning pass
cannot pair them (docs/DESIGN.md, Hot path). This counts them. A child process loads the
network, compiles the kernels into a fresh numba cache directory (their machine code can then
be listed: about a minute), matches the traces once (match + GeoJSON), lists the address of
every compiled function, and matches them again under gdb (Debian's ``gdb``), which counts
each call of ``NRT_incref`` and ``NRT_decref`` by its return address. Each count goes to the
compiled function it returns into: the kernel, or a helper LLVM left standing. Slow (a
breakpoint a count: about a minute for 20 traces of 15 s); counts, not times.

The traces: ``--traces`` simulated trips on the extract, ``--fixes`` fixes each at
``--interval`` (heading and speed given, 2 % outliers of 40 m), or every trace of ``--csv``
matched with ``--sigma`` (stop 52's figures: the Krems 15 s positions of the peer sets,
``.bench/peers/sets/krems_at_2013/15s_10m/positions.csv --sigma 10``).
"""

from __future__ import annotations

import argparse
import bisect
import collections
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from kernel_time import add_trace_arguments

#: The environment variable that tells the process its part (the child or gdb's side).
_ROLE = "COUNT_REFCOUNTS_ROLE"
_DIR = "COUNT_REFCOUNTS_DIR"


def _name(symbol: str) -> str:
    """``mapmatch.hmm.pathwalk._continue_from`` of numba's mangled symbol (else the symbol)."""
    match = re.match(r"_ZN(?:7cpython)?((?:\d+[A-Za-z_]\w*?)+?)B\d", symbol)
    if match is None:
        return symbol
    parts, rest = [], match.group(1)
    while rest:
        size = re.match(r"\d+", rest)
        if size is None:
            break
        start = size.end()
        parts.append(rest[start : start + int(size.group())])
        rest = rest[start + int(size.group()) :]
    return ".".join(parts)


def _child(args: argparse.Namespace, workdir: Path) -> None:
    """Load, compile, list the compiled functions, then match again once gdb is attached."""
    from kernel_time import network_and_traces, our_kernels

    import mapmatch
    from mapmatch.export import geojson_bytes

    net, traces, config = network_and_traces(args)
    for trace in traces:
        geojson_bytes(mapmatch.match(trace, net, config))
    functions: set[tuple[int, str]] = set()
    for _, _, kernel in our_kernels():
        for compiled in kernel.overloads.values():
            library = compiled.library
            for function in library._final_module.functions:
                if not function.is_declaration:
                    functions.add((library.get_pointer_to_function(function.name), function.name))
    lines = [f"{address:x} {name}" for address, name in sorted(functions) if address]
    (workdir / "functions.txt").write_text("\n".join(lines) + "\n")
    print("READY", os.getpid(), len(traces), flush=True)
    while not (workdir / "armed").exists():  # gdb has set its breakpoints
        time.sleep(0.05)
    for trace in traces:
        geojson_bytes(mapmatch.match(trace, net, config))
    os.kill(os.getpid(), signal.SIGUSR1)  # hands control back to gdb


def _gdb_side(workdir: Path) -> None:  # pragma: no cover - runs inside gdb
    """Count each call of the two functions by return address; write the counts; kill."""
    import gdb  # type: ignore[import-untyped]

    counts: collections.Counter[tuple[str, int]] = collections.Counter()

    class Counting(gdb.Breakpoint):  # type: ignore[misc]
        def stop(self) -> bool:
            ret = int(gdb.parse_and_eval("*(unsigned long *)$sp"))
            counts[(self.kind, ret)] += 1
            return False

    seen = set()
    for line in (workdir / "functions.txt").read_text().splitlines():
        address, name = line.split(maxsplit=1)
        if name in ("NRT_incref", "NRT_decref") and address not in seen:
            seen.add(address)
            Counting(f"*0x{address}", internal=True).kind = name
    (workdir / "armed").touch()
    gdb.execute("continue")
    (workdir / "counts.txt").write_text(
        "\n".join(f"{kind} {ret:x} {n}" for (kind, ret), n in counts.items()) + "\n"
    )
    gdb.execute("kill")


def _report(workdir: Path, traces: int, top: int) -> None:
    """Counts per trace by the function each returns into, largest first."""
    functions = []
    for line in (workdir / "functions.txt").read_text().splitlines():
        address, name = line.split(maxsplit=1)
        functions.append((int(address, 16), name))
    starts = [a for a, _ in functions]
    by_function: collections.Counter[str] = collections.Counter()
    for line in (workdir / "counts.txt").read_text().splitlines():
        _, ret, hits = line.split()
        at = bisect.bisect_right(starts, int(ret, 16)) - 1
        by_function[_name(functions[at][1]) if at >= 0 else "?"] += int(hits)
    total = sum(by_function.values())
    print(f"{total / traces:,.0f} reference counts a trace ({traces} traces)")
    for name, n in by_function.most_common(top):
        print(f"{n / traces:9,.0f}  {name}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(parser)
    parser.add_argument("--top", type=int, default=25, help="functions listed")
    args = parser.parse_args(argv)
    role = os.environ.get(_ROLE)
    if role == "child":
        _child(args, Path(os.environ[_DIR]))
        return 0
    if shutil.which("gdb") is None:
        print("count_refcounts needs gdb (Debian: apt-get install gdb)", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        env = dict(
            os.environ, NUMBA_CACHE_DIR=str(workdir / "numba"), **{_ROLE: "child", _DIR: tmp}
        )
        child = subprocess.Popen(
            [sys.executable, __file__, *(argv if argv is not None else sys.argv[1:])],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert child.stdout is not None
        ready = child.stdout.readline().split()
        if ready[:1] != ["READY"]:
            child.wait()
            print("the child process did not get ready", file=sys.stderr)
            return 1
        gdb_env = dict(os.environ, **{_ROLE: "gdb", _DIR: tmp})
        debugger = subprocess.run(
            ["gdb", "-p", ready[1], "-batch", "-x", __file__],
            env=gdb_env,
            check=False,
            capture_output=True,
            text=True,
        )
        if not (workdir / "counts.txt").exists():  # gdb could not attach or count: say why
            child.kill()
            child.wait()
            print("gdb counted nothing:", debugger.stderr.strip()[-2000:], file=sys.stderr)
            return 1
        child.wait()
        _report(workdir, int(ready[2]), args.top)
    return 0


if __name__ == "__main__":
    if os.environ.get(_ROLE) == "gdb":
        _gdb_side(Path(os.environ[_DIR]))
    else:
        sys.exit(main())
