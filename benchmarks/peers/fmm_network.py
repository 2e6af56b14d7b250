"""Our compiled road network written as FMM's edge shapefile, and FMM's UBODT built for it.

Runs in the project venv (it reads :class:`roadnets.RoadNetwork` arrays), so FMM matches on
exactly the roads every other matcher here sees: the same drivable ways, the same directions,
the same UTM geometry.

FMM reads an ESRI shapefile of directed edges (integer fields ``id``, ``source``, ``target``,
LineString geometry in a metric CRS; one feature per direction of a two-way road). Two layouts:

``segments`` (default)
    One FMM edge per geometry segment of each of our directed edges (one per OSM node pair, as
    an unsimplified osmnx graph). FMM's ``reverse_tolerance`` is a fraction of one edge's
    length, so short edges keep it meaningful; this is the layout FMM is accurate on. Interior
    vertices become nodes shared by an edge and its twin (the same OSM node both ways).
``edges``
    One FMM edge per directed edge of ours (the simplified graph): a far smaller UBODT, but
    FMM is less accurate on it.

Consecutive duplicate vertices are merged so that no FMM edge has zero length (FMM divides by
edge lengths); edges whose whole geometry has zero length are left out and counted.

The UBODT (FMM's upper-bounded origin-destination table) comes from FMM's own ``ubodt_gen``.
Both are cached under ``.bench/fmm/cache/<extract stem>-<source sha>-<layout>/`` and rebuilt
only when the extract, the layout or ``delta`` changes.
"""

from __future__ import annotations

import json
import subprocess
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from roadnets import RoadNetwork

__all__ = [
    "LAYOUTS",
    "FmmEdgeFile",
    "FmmFiles",
    "build_ubodt",
    "fmm_edges",
    "prepare",
    "write_edge_file",
]

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_BUILD = ROOT / ".bench" / "fmm"
LAYOUTS = ("segments", "edges")
DEFAULT_DELTA_M = 3000.0


@dataclass(frozen=True, slots=True)
class FmmEdges:
    """FMM edges as arrays: edge ``i`` runs ``source[i] -> target[i]`` over its vertices."""

    id: npt.NDArray[np.int64]
    source: npt.NDArray[np.int64]
    target: npt.NDArray[np.int64]
    our_edge: npt.NDArray[np.int64]
    ptr: npt.NDArray[np.int64]
    x: npt.NDArray[np.float64]
    y: npt.NDArray[np.float64]
    dropped_zero_length: int
    merged_duplicate_vertices: int

    def __len__(self) -> int:
        return len(self.id)


@dataclass(frozen=True, slots=True)
class FmmEdgeFile:
    """What :func:`write_edge_file` wrote."""

    path: str
    layout: str
    crs: str
    edges: int
    nodes: int
    our_edges: int
    dropped_zero_length: int
    merged_duplicate_vertices: int
    write_s: float


@dataclass(frozen=True, slots=True)
class FmmFiles:
    """A cached FMM network: edge shapefile, UBODT and the facts about both."""

    edges_shp: str
    ubodt: str
    crs: str
    layout: str
    delta_m: float
    edge_file: dict[str, object]
    ubodt_s: float
    ubodt_mb: float
    from_cache: bool


def fmm_edges(net: RoadNetwork, layout: str = "segments") -> FmmEdges:
    """
    FMM's directed edges for a network, in our edge order.

    Parameters
    ----------
    net
        A loaded network.
    layout
        ``"segments"`` (one FMM edge per geometry segment) or ``"edges"`` (one per edge).

    Returns
    -------
    FmmEdges
        ``id`` counts from 1; ``source``/``target`` are our node indices for graph nodes and
        ``n_nodes + k`` for interior vertices, which an edge and its twin share (a twin runs
        the same vertices backwards).

    Raises
    ------
    ValueError
        Unknown layout, or a twin whose geometry is not its partner's reversed.
    """
    if layout not in LAYOUTS:
        msg = f"unknown FMM edge layout {layout!r}; choose one of {LAYOUTS}"
        raise ValueError(msg)
    a = net.arrays
    next_node = a.n_nodes
    # canonical edge (the smaller of a twin pair) -> (kept vertex indices, their node ids)
    kept_of: dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = {}
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("src", "tgt", "our", "x", "y", "n")}
    dropped = merged = 0
    for e in range(a.n_edges):
        lo, hi = int(a.edge_geom_ptr[e]), int(a.edge_geom_ptr[e + 1])
        twin = int(a.edge_twin[e])
        if twin >= 0 and twin < e:
            t_lo, t_hi = int(a.edge_geom_ptr[twin]), int(a.edge_geom_ptr[twin + 1])
            if t_hi - t_lo != hi - lo or not np.array_equal(
                a.geom_x[lo:hi], a.geom_x[t_lo:t_hi][::-1]
            ):
                msg = f"edge {e} and its twin {twin} do not share reversed geometry"
                raise ValueError(msg)
            kept_c, ids_c = kept_of[twin]
            kept, node_ids = (hi - lo - 1) - kept_c[::-1], ids_c[::-1]
        else:
            kept = _kept_vertices(a.geom_cum_m[lo:hi])
            merged += (hi - lo) - len(kept)
            if layout == "edges" or len(kept) < 2:
                node_ids = np.array([a.edge_u[e], a.edge_v[e]], dtype=np.int64)
            else:
                inner = np.arange(next_node, next_node + len(kept) - 2, dtype=np.int64)
                next_node += len(kept) - 2
                node_ids = np.concatenate(([a.edge_u[e]], inner, [a.edge_v[e]])).astype(np.int64)
            kept_of[e] = (kept, node_ids)
        if len(kept) < 2:  # the whole geometry has zero length
            dropped += 1
            continue
        gx, gy = a.geom_x[lo:hi][kept], a.geom_y[lo:hi][kept]
        if layout == "edges":
            parts["x"].append(gx)
            parts["y"].append(gy)
            parts["n"].append(np.array([len(kept)]))
            parts["src"].append(node_ids[:1])
            parts["tgt"].append(node_ids[-1:])
            parts["our"].append(np.array([e]))
            continue
        k = len(kept) - 1  # segment j runs from kept vertex j to j + 1
        parts["x"].append(np.column_stack([gx[:-1], gx[1:]]).ravel())
        parts["y"].append(np.column_stack([gy[:-1], gy[1:]]).ravel())
        parts["n"].append(np.full(k, 2))
        parts["src"].append(node_ids[:-1])
        parts["tgt"].append(node_ids[1:])
        parts["our"].append(np.full(k, e))

    def cat(name: str, dtype: type) -> np.ndarray:
        chunks = parts[name]
        return np.concatenate(chunks).astype(dtype) if chunks else np.empty(0, dtype=dtype)

    sizes = cat("n", np.int64)
    return FmmEdges(
        id=np.arange(1, len(sizes) + 1, dtype=np.int64),
        source=cat("src", np.int64),
        target=cat("tgt", np.int64),
        our_edge=cat("our", np.int64),
        ptr=np.concatenate(([0], np.cumsum(sizes))).astype(np.int64),
        x=cat("x", np.float64),
        y=cat("y", np.float64),
        dropped_zero_length=dropped,
        merged_duplicate_vertices=merged,
    )


def _kept_vertices(cum: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    """Vertices left when consecutive duplicates merge (the first and the last always stay)."""
    keep = [0]
    for i in range(1, len(cum)):
        if cum[i] > cum[keep[-1]]:
            keep.append(i)
        elif i == len(cum) - 1 and len(keep) > 1:
            keep[-1] = i  # the end replaces an interior duplicate of it
    return np.asarray(keep, dtype=np.int64)


def write_edge_file(net: RoadNetwork, path: Path, layout: str = "segments") -> FmmEdgeFile:
    """
    Write the network as FMM's edge shapefile (``path`` ends in ``.shp``).

    Fields: ``id``, ``source``, ``target`` (what FMM reads) and ``our_edge`` (our directed edge
    index, for looking results up). CRS: the network's UTM zone.
    """
    import geopandas as gpd  # type: ignore[import-untyped]
    import shapely

    t0 = time.perf_counter()
    fe = fmm_edges(net, layout)
    coords = np.column_stack([fe.x, fe.y])
    index = np.repeat(np.arange(len(fe)), np.diff(fe.ptr))
    lines = shapely.linestrings(coords, indices=index)
    frame = gpd.GeoDataFrame(
        {"id": fe.id, "source": fe.source, "target": fe.target, "our_edge": fe.our_edge},
        geometry=lines,
        crs=net.crs,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_file(path, driver="ESRI Shapefile", engine="pyogrio")
    nodes = int(np.unique(np.concatenate([fe.source, fe.target])).size) if len(fe) else 0
    return FmmEdgeFile(
        path=str(path),
        layout=layout,
        crs=net.crs,
        edges=len(fe),
        nodes=nodes,
        our_edges=net.arrays.n_edges,
        dropped_zero_length=fe.dropped_zero_length,
        merged_duplicate_vertices=fe.merged_duplicate_vertices,
        write_s=time.perf_counter() - t0,
    )


def build_ubodt(
    edges_shp: Path, out: Path, delta_m: float, build_dir: Path = DEFAULT_BUILD
) -> float:
    """Run FMM's ``ubodt_gen`` on an edge file; return its wall seconds."""
    exe = build_dir / "src" / "build" / "ubodt_gen"
    if not exe.exists():
        msg = f"{exe} missing; build FMM first: bash benchmarks/peers/setup.sh"
        raise FileNotFoundError(msg)
    t0 = time.perf_counter()
    r = subprocess.run(
        [
            str(exe),
            "--network",
            str(edges_shp),
            "--output",
            str(out),
            "--delta",
            f"{delta_m:g}",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    if r.returncode != 0 or not out.exists():
        tail = (r.stdout + r.stderr).strip().splitlines()[-5:]
        msg = f"ubodt_gen failed on {edges_shp} (exit {r.returncode}): {' | '.join(tail)}"
        raise RuntimeError(msg)
    return time.perf_counter() - t0


def prepare(
    extract: Path,
    *,
    layout: str = "segments",
    delta_m: float = DEFAULT_DELTA_M,
    build_dir: Path = DEFAULT_BUILD,
) -> FmmFiles:
    """
    The cached FMM edge file and UBODT for an extract, built when missing or stale.

    The key is the extract's stem, the first 12 hex digits of its SHA-256, the layout and
    ``delta``; a ``meta.json`` beside the files records how they were made.
    """
    import roadnets

    net = roadnets.load(extract)
    stem = Path(extract).name.split(".")[0]
    folder = build_dir / "cache" / f"{stem}-{net.source_sha256[:12]}-{layout}"
    shp = folder / "edges.shp"
    ubodt = folder / f"ubodt_{delta_m:g}.bin"
    meta_path = folder / f"meta_{delta_m:g}.json"
    if meta_path.exists() and shp.exists() and ubodt.exists():
        meta = json.loads(meta_path.read_text())
        return FmmFiles(**(meta | {"from_cache": True}))
    edge_file = write_edge_file(net, shp, layout)
    ubodt_s = build_ubodt(shp, ubodt, delta_m, build_dir)
    files = FmmFiles(
        edges_shp=str(shp),
        ubodt=str(ubodt),
        crs=net.crs,
        layout=layout,
        delta_m=delta_m,
        edge_file=asdict(edge_file),
        ubodt_s=ubodt_s,
        ubodt_mb=ubodt.stat().st_size / 2**20,
        from_cache=False,
    )
    meta_path.write_text(json.dumps(asdict(files), indent=1))
    return files
