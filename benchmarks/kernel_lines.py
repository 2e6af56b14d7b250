"""Where a compiled kernel's time goes, statement by statement.

    .venv/bin/python benchmarks/kernel_lines.py --kernel mapmatch.hmm.trellis.solve_kernel
        [--reach transitions_kernel,_pair_routes] [--depth 2] [--top 20] [--loops 31]
        [--extract PATH] [--csv TRACES.csv --sigma 20] [--interval 15 --fixes 25 --traces 20]

A profiler of Python (py-spy, cProfile) sees a numba kernel as one opaque frame, and
``kernel_time.py`` times kernels whole. This script opens one up: the traces are matched once
(match + GeoJSON, as a user of the library gets them) with ``--kernel`` (a kernel called from
Python, named by its module and function) replaced by a stand-in that keeps the arguments of
every call; then a copy of a kernel is compiled with a read of the CPU's time-stamp counter
(LLVM's ``readcyclecounter``) after each of its statements, and run on the kept calls
``--loops`` times in a row. The table gives each statement's median cost a call, in
microseconds, and its share of the copy's time. ``--reach`` profiles a kernel that one
calls (each name a global of the one before it, ``solve_kernel`` ->
``transitions_kernel`` -> ``_pair_routes``): the chain is compiled again from its source so
that the copy is the one called. Statements inside loops and branches are split down to
``--depth`` levels (1: the function's own statements; a loop's line then counts the whole
loop).

What it measures, and what not: a warm loop over the kept calls (in the flow a kernel runs
colder: ``kernel_time.py`` says by how much); the counter reads keep LLVM from moving work
across statements, so the copy's time differs a little from the kernel's (both are printed,
on the same calls). Its first finding: ``angle_between`` spent 14 us of a Krems 30 s trace's
solve in libm's ``fmod`` on NaN courses. The copy is compiled fresh, never cached (it holds
this process's address of the counters), a few seconds to a minute.
"""

from __future__ import annotations

import argparse
import ast
import functools
import importlib
import inspect
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parent)]
from kernel_time import add_trace_arguments, network_and_traces, our_kernels  # noqa: E402

if TYPE_CHECKING:
    from collections.abc import Callable

#: Counters a profiled copy can write: one per statement instrumented.
MAX_STATEMENTS = 2000


@dataclass(frozen=True, slots=True)
class Statement:
    """One instrumented statement: its line in its file, its nesting level and its text."""

    line: int
    level: int
    text: str


@functools.cache
def _cycle_reader() -> tuple[Any, Any]:
    """The compiled ``rdtsc()`` and ``counters_at(address, n)`` a profiled copy calls; made once."""
    from llvmlite import ir
    from numba import carray, njit, types
    from numba.extending import intrinsic

    @intrinsic  # type: ignore[misc]
    def rdtsc(typingctx):  # type: ignore[no-untyped-def]
        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            fnty = ir.FunctionType(ir.IntType(64), [])
            fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=fnty)
            return builder.call(fn, [])

        return types.uint64(), codegen

    @intrinsic  # type: ignore[misc]
    def _pointer(typingctx, address):  # type: ignore[no-untyped-def]
        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            return builder.inttoptr(args[0], ir.IntType(8).as_pointer())

        return types.voidptr(types.intp), codegen

    @njit(inline="always")  # type: ignore[misc]
    def counters_at(address, n):  # type: ignore[no-untyped-def]
        return carray(_pointer(address), n, np.uint64)

    return rdtsc, counters_at


def _counter_rate(rdtsc: Any) -> float:
    """Counter ticks per second, against ``time.perf_counter`` over a tenth of a second."""
    from numba import njit

    read = njit(lambda: rdtsc())
    read()
    t0, c0 = time.perf_counter(), read()
    time.sleep(0.1)
    t1, c1 = time.perf_counter(), read()
    return float(c1 - c0) / (t1 - t0)


def instrumented_source(
    func: Callable[..., Any], address: int, depth: int, statements: list[Statement]
) -> str:
    """
    ``func``'s source with a counter read after each statement, down to ``depth`` levels.

    The ticks since the previous read go to counter ``len(statements)`` at that moment, and
    the statement is appended to ``statements``; a ``return``, ``break`` or ``continue`` is
    counted before it runs (nothing after it would).
    """
    lines, first_line = inspect.getsourcelines(func)
    source = textwrap.dedent("".join(lines))
    tree = ast.parse(source)
    definition = tree.body[0]
    assert isinstance(definition, ast.FunctionDef)
    definition.decorator_list = []
    source_lines = source.splitlines()

    def timer(slot: int) -> list[ast.stmt]:
        return ast.parse(f"_t1 = rdtsc(); _ticks[{slot}] += _t1 - _t0; _t0 = _t1").body

    def instrument(body: list[ast.stmt], level: int) -> list[ast.stmt]:
        out: list[ast.stmt] = []
        for statement in body:
            if level + 1 < depth and isinstance(statement, (ast.For, ast.While, ast.If)):
                statement.body = instrument(statement.body, level + 1)
                if isinstance(statement, ast.If) and statement.orelse:
                    statement.orelse = instrument(statement.orelse, level + 1)
            slot = len(statements)
            text = source_lines[statement.lineno - 1].strip()
            statements.append(Statement(first_line + statement.lineno - 1, level, text))
            if isinstance(statement, (ast.Return, ast.Break, ast.Continue)):
                out += [*timer(slot), statement]
            else:
                out += [statement, *timer(slot)]
        return out

    body = definition.body
    first = body[0] if body else None
    documented = (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    )
    docstring = body[:1] if documented else []
    start = ast.parse(f"_ticks = counters_at({address}, {MAX_STATEMENTS})\n_t0 = rdtsc()").body
    definition.body = [*docstring, *start, *instrument(body[len(docstring) :], 0)]
    if len(statements) > MAX_STATEMENTS:
        msg = f"{len(statements)} statements: more than {MAX_STATEMENTS} (lower --depth)"
        raise SystemExit(msg)
    return ast.unparse(ast.fix_missing_locations(tree))


def _compiled(source: str, name: str, namespace: dict[str, Any]) -> Any:
    from numba import njit

    exec(compile(source, f"<profiled {name}>", "exec"), namespace)
    return njit(namespace[name])


def profiled_chain(
    top: Any, reach: list[str], address: int, depth: int, statements: list[Statement]
) -> tuple[Any, Any]:
    """
    ``(copy of top, the kernel profiled)``: ``top`` compiled again with the kernel it reaches
    through ``reach`` (global names, each in the module of the one before) instrumented.
    """
    chain = [top]
    for name in reach:
        callee = chain[-1].py_func.__globals__.get(name)
        if callee is None or not hasattr(callee, "py_func"):
            msg = f"{name} is not a kernel {chain[-1].py_func.__name__} calls"
            raise SystemExit(msg)
        chain.append(callee)
    rdtsc, counters_at = _cycle_reader()
    target = chain[-1]
    namespace = dict(target.py_func.__globals__, rdtsc=rdtsc, counters_at=counters_at)
    source = instrumented_source(target.py_func, address, depth, statements)
    compiled = _compiled(source, target.py_func.__name__, namespace)
    for parent, callee_name in zip(reversed(chain[:-1]), reversed(reach), strict=True):
        lines = textwrap.dedent(inspect.getsource(parent.py_func)).splitlines()
        source = "\n".join(line for line in lines if not line.startswith("@"))
        namespace = dict(parent.py_func.__globals__, **{callee_name: compiled})
        compiled = _compiled(source, parent.py_func.__name__, namespace)
    return compiled, target


def kept_calls(
    kernel_name: str, match_all: Callable[[], None]
) -> tuple[Any, list[tuple[Any, ...]]]:
    """``(kernel, the arguments of each call of it while match_all ran)``."""
    module_name, _, name = kernel_name.rpartition(".")
    kernel = getattr(importlib.import_module(module_name), name, None)
    if kernel is None or not hasattr(kernel, "py_func"):
        msg = f"{kernel_name} is not a compiled kernel"
        raise SystemExit(msg)
    kept: list[tuple[Any, ...]] = []

    def stand_in(*args: Any) -> Any:
        kept.append(args)
        return kernel(*args)

    bound = [(module, attr) for module, attr, value in our_kernels() if value is kernel]
    for module, attr in bound:
        setattr(module, attr, stand_in)
    try:
        match_all()
    finally:  # the modules get their kernel back (a test's process matches on)
        for module, attr in bound:
            setattr(module, attr, kernel)
    if not kept:
        msg = f"the matches never called {kernel_name} from Python"
        raise SystemExit(msg)
    return kernel, kept


def _seconds_a_call(kernel: Any, calls: list[tuple[Any, ...]]) -> float:
    start = time.perf_counter()
    for args in calls:
        kernel(*args)
    return (time.perf_counter() - start) / len(calls)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(parser)
    parser.add_argument("--kernel", default="mapmatch.hmm.trellis.solve_kernel")
    parser.add_argument("--reach", default="", help="callees to follow, comma-separated")
    parser.add_argument("--depth", type=int, default=1, help="levels of loops split")
    parser.add_argument("--top", type=int, default=20, help="statements shown")
    parser.add_argument("--loops", type=int, default=31, help="loops over the kept calls")
    args = parser.parse_args(argv)
    net, traces, config = network_and_traces(args)

    import mapmatch
    from mapmatch.export import geojson_bytes

    def match_all() -> None:
        for trace in traces:
            geojson_bytes(mapmatch.match(trace, net, config))

    match_all()  # compiles or loads every kernel the traces need
    kernel, calls = kept_calls(args.kernel, match_all)
    ticks = np.zeros(MAX_STATEMENTS, dtype=np.uint64)
    statements: list[Statement] = []
    reach = [name for name in args.reach.split(",") if name]
    copy, target = profiled_chain(kernel, reach, ticks.ctypes.data, args.depth, statements)
    rdtsc, _ = _cycle_reader()
    rate = _counter_rate(rdtsc)
    for call in calls:  # compiles the copy
        copy(*call)
    per_loop, original, instrumented = [], [], []
    for _ in range(max(1, args.loops)):
        ticks[:] = 0
        instrumented.append(_seconds_a_call(copy, calls))
        per_loop.append(ticks[: len(statements)].astype(np.float64) / len(calls))
        original.append(_seconds_a_call(kernel, calls))
    us = 1e6 / rate * np.median(np.array(per_loop), axis=0)
    total = float(us.sum())
    name = ".".join([kernel.py_func.__name__, *reach])
    print(
        f"{name}: {len(calls)} calls from {len(traces)} traces; a call "
        f"{np.median(original) * 1e6:.1f} us, the profiled copy "
        f"{np.median(instrumented) * 1e6:.1f} us, of which the statements of "
        f"{target.py_func.__name__} {total:.1f} us (counter at {rate / 1e9:.2f} GHz,"
        f" medians of {len(per_loop)} loops)"
    )
    print()
    print("| us a call | share | line | statement |")
    print("|--:|--:|--:|---|")
    file = Path(inspect.getsourcefile(target.py_func) or "?").name
    for slot in np.argsort(-us)[: args.top]:
        statement = statements[slot]
        share = us[slot] / total if total > 0 else 0.0
        text = ("  " * statement.level + statement.text).replace("|", "\\|")
        print(f"| {us[slot]:.2f} | {share:.1%} | {file}:{statement.line} | `{text}` |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
