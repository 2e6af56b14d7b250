from __future__ import annotations

import numpy as np
import pytest

from mapmatch.config import MatchConfig
from mapmatch.errors import ConfigError
from mapmatch.hmm.emission import angle_between, heading_weight, log_emission, log_heading
from mapmatch.hmm.routes import ROUTE_SAME_EDGE, ROUTE_UTURN, ROUTE_VIA_GRAPH, candidate_pairs
from mapmatch.hmm.transition import TRAVEL_CHORD_SHARE, driving_on_explains, log_transition


def test_emission_is_gaussian_in_distance() -> None:
    d = np.array([0.0, 5.0, 10.0])
    assert log_emission(d, sigma_m=5.0).tolist() == [0.0, -0.5, -2.0]


def test_heading_counts_more_the_faster_the_car() -> None:
    cfg = MatchConfig()
    speeds = np.array([0.0, 1.0, 5.5, 10.0, 30.0])
    w = heading_weight(speeds, cfg)
    assert w.tolist() == [0.0, 0.0, 0.5, 1.0, 1.0]
    wrong = log_heading(np.full(5, 0.0), np.full(5, 180.0), w, cfg)
    assert wrong[0] == 0.0
    assert wrong[2] == pytest.approx(-0.5 * cfg.heading_max_penalty)
    assert wrong[4] == -cfg.heading_max_penalty
    # a small disagreement costs little, and angles wrap around north
    near = log_heading(np.array([355.0]), np.array([5.0]), np.array([1.0]), cfg)
    assert near[0] == pytest.approx(-0.5 * (10 / cfg.heading_sigma_deg) ** 2)
    assert log_heading(np.array([np.nan]), np.array([5.0]), np.array([1.0]), cfg)[0] == 0.0


def test_angle_between_is_the_modulo_formula_nan_included() -> None:
    # the compiled function returns NaN before its modulo: the same values as the formula
    values = [0.0, 5.0, 179.9, 180.0, 355.0, 359.99, -90.0, 720.5, np.nan, np.inf, -np.inf]
    for a in values:
        for b in values:
            want = abs((a - b + 180.0) % 360.0 - 180.0)
            got = angle_between(a, b)
            assert (np.isnan(got) and np.isnan(want)) or got == want, (a, b, got, want)


def test_transition_is_exponential_in_the_distance_mismatch() -> None:
    cfg = MatchConfig(beta_m=4.0, beta_per_s=0.0, beta_per_sigma=0.0)
    one = np.ones(3)
    lt = log_transition(
        np.array([10.0, 10.0, 10.0]),
        np.array([10.0, 14.0, np.inf]),
        np.array([1.0, 1.0, 1.0]),
        np.full(3, ROUTE_VIA_GRAPH),
        one,
        one * 5,
        cfg,
    )
    assert lt[0] == 0.0
    assert lt[1] == pytest.approx(-1.0)
    assert lt[2] == -np.inf


def test_implausible_speed_and_u_turns_cost_extra() -> None:
    cfg = MatchConfig()
    gc = np.array([100.0, 100.0])
    route = np.array([100.0, 100.0])
    free_time = np.array([1.0, 10.0])  # free-flow time of the path at its speed limits
    lt = log_transition(
        gc, route, free_time, np.full(2, ROUTE_VIA_GRAPH), np.full(2, 1.0), np.full(2, 5.0), cfg
    )
    # 100 m in 1 s on roads limited to 10 m/s (second) is implausible; at 100 m/s limits it is not
    assert lt[0] == 0.0
    assert lt[1] < -10
    kinds = np.array([ROUTE_SAME_EDGE, ROUTE_UTURN])
    lu = log_transition(
        np.full(2, 20.0),
        np.full(2, 20.0),
        np.full(2, 10.0),
        kinds,
        np.full(2, 2.0),
        np.full(2, 5.0),
        cfg,
    )
    assert lu[0] - lu[1] == pytest.approx(cfg.uturn_penalty)


def test_a_heading_that_turned_round_is_no_u_turn_evidence_where_the_road_turns() -> None:
    # a car heading east at offset 50 m of edge 7, then west: evidence of a U-turn on a
    # straight road, none where a candidate ahead on edge 7 points west (a hairpin)
    edge = np.array([7, 7, 8])
    offset = np.array([20.0, 300.0, 10.0])
    bearing = np.array([270.0, 265.0, 270.0])
    assert driving_on_explains(7, 50.0, 270.0, 0, 3, edge, offset, bearing)
    assert not driving_on_explains(7, 50.0, 270.0, 0, 1, edge, offset, bearing)  # behind
    assert not driving_on_explains(7, 50.0, 90.0, 0, 3, edge, offset, bearing)  # against
    assert not driving_on_explains(9, 0.0, 270.0, 0, 3, edge, offset, bearing)  # other road


def test_reported_travel_only_counts_outside_its_tolerance() -> None:
    cfg = MatchConfig()
    gc = np.full(3, 50.0)
    route = np.array([50.0, 55.0, 120.0])
    travel = (np.full(3, 50.0), np.zeros(3))
    lt = log_transition(
        gc,
        np.array([50.0, 50.0, 50.0]),
        np.full(3, 5.0),
        np.full(3, ROUTE_VIA_GRAPH),
        np.full(3, 5.0),
        np.full(3, 5.0),
        cfg,
        travel,
    )
    assert lt.tolist() == [0.0, 0.0, 0.0]
    lt = log_transition(
        gc,
        route,
        np.full(3, 5.0),
        np.full(3, ROUTE_VIA_GRAPH),
        np.full(3, 5.0),
        np.full(3, 5.0),
        cfg,
        travel,
    )
    base = -np.abs(gc - route) / (cfg.beta_m + cfg.beta_per_s * 5.0 + cfg.beta_per_sigma * 5.0)
    tolerance = cfg.travel_tolerance_m + cfg.travel_tolerance_frac * 50.0
    assert lt[1] == pytest.approx(base[1])  # 5 m off is inside the tolerance
    assert lt[2] == pytest.approx(base[2] - (70.0 - tolerance) / cfg.travel_beta_m)


def test_a_winding_route_that_the_travel_confirms_is_not_charged_for_its_chord() -> None:
    # 200 m of hairpin between fixes 20 m apart: the chord alone calls that 180 m of detour;
    # an odometer that says 200 m (no slack) explains all but a share of it, two speeds 15 s
    # apart do not
    cfg = MatchConfig()
    args = (np.full(2, 20.0), np.full(2, 200.0), np.full(2, 15.0))
    kind, dt, sigma = np.full(2, ROUTE_VIA_GRAPH), np.full(2, 15.0), np.full(2, 5.0)
    travel = (np.full(2, 200.0), np.array([0.0, 100.0]))
    lt = log_transition(*args, kind, dt, sigma, cfg, travel)
    beta = cfg.beta_m + cfg.beta_per_s * 15.0 + cfg.beta_per_sigma * 5.0
    assert lt.tolist() == pytest.approx([-TRAVEL_CHORD_SHARE * 180.0 / beta, -180.0 / beta])


def test_candidate_pairs_cover_every_pair_of_consecutive_fixes() -> None:
    ptr = np.array([0, 3, 3, 5, 6])  # fix 1 has no candidate
    pairs = candidate_pairs(ptr)
    got = set(zip(pairs.a.tolist(), pairs.b.tolist(), strict=True))
    assert got == {(3, 5), (4, 5)}
    assert pairs.step.tolist() == [2, 2]
    assert pairs.a_rank.tolist() == [0, 1]


@pytest.mark.parametrize(
    ("field", "value", "needle"),
    [
        ("sigma_m", -1.0, "sigma_m must be > 0 (got -1)"),
        ("sigma_m", float("nan"), "sigma_m must be a finite number"),
        ("search_radius_m", 10_000.0, "search_radius_m must be <= 200 (got 10000)"),
        ("max_search_radius_m", 40.0, "search_radius_m must be <= max_search_radius_m"),
        ("max_candidates", 0, "max_candidates must be >= 1 (got 0)"),
        ("max_candidates", 2.5, "max_candidates must be a whole number"),
        ("use_travel", 1, "use_travel must be true or false"),
        ("beta_m", 0.0, "beta_m must be > 0"),
        ("distance_band", (0.01, -0.04), "distance_band"),
    ],
)
def test_config_errors_name_the_field_and_value(field: str, value: object, needle: str) -> None:
    with pytest.raises(ConfigError) as caught:
        MatchConfig(**{field: value})  # type: ignore[arg-type]
    assert needle in str(caught.value)
    assert caught.value.field in (field, "search_radius_m")


def test_config_overrides_are_limited_to_the_documented_fields() -> None:
    cfg = MatchConfig().replace({"sigma_m": 7.0, "distance_band": [-0.05, 0.02]})
    assert cfg.sigma_m == 7.0
    assert cfg.distance_band == (-0.05, 0.02)
    with pytest.raises(ConfigError, match="unknown option"):
        MatchConfig().replace({"route_slack_m": 5.0})
    with pytest.raises(ConfigError, match="sigma_m must be > 0"):
        MatchConfig().replace({"sigma_m": -1})


@pytest.mark.parametrize(
    ("sigma_m", "accuracy", "radius"),
    [
        (5.0, None, [50.0, 50.0, 50.0]),  # four sigmas inside the search radius: the radius
        (20.0, None, [80.0, 80.0, 80.0]),  # a configured sigma widens every fix's radius
        (5.0, [3.0, 30.0, np.nan], [50.0, 120.0, 50.0]),  # a poor accuracy widens its own
        (20.0, [3.0, 30.0, 90.0], [80.0, 120.0, 200.0]),  # the larger sigma, at most 200 m
    ],
)
def test_a_fix_searches_four_of_its_sigmas(
    sigma_m: float, accuracy: list[float] | None, radius: list[float]
) -> None:
    from mapmatch.hmm.fixes import fixes_of
    from mapmatch.trace import Trace

    lon, lat = [7.42, 7.421, 7.422], [43.73, 43.73, 43.73]
    trace = Trace(time=[0.0, 30.0, 60.0], lon=lon, lat=lat, accuracy=accuracy)
    x, y = np.array([0.0, 80.0, 160.0]), np.zeros(3)
    fixes = fixes_of(trace, x, y, MatchConfig(sigma_m=sigma_m))
    assert fixes.radius_m.tolist() == radius


def test_holds_across_edges_route_only_the_pairs_the_road_could_hold(default_net) -> None:  # type: ignore[no-untyped-def]
    # a pair whose rest of b's edge and a's offset already exceed the tolerance is not routed;
    # the rest are routed with the bound routing every pair near in the plane gives their b
    # edge, so the distances behind are those of routing them all
    from mapmatch.hmm.routes import held_across, held_behind

    arrays = default_net.arrays
    rng = np.random.default_rng(7)
    eb = np.repeat(rng.integers(0, arrays.n_edges, 150), 3)  # each b edge in three steps
    nexts = [arrays.out_edge[arrays.out_ptr[v] : arrays.out_ptr[v + 1]] for v in arrays.edge_v[eb]]
    keep = np.array([len(n) > 0 for n in nexts])
    eb = eb[keep]
    ea = np.array([rng.choice(n) for n, k in zip(nexts, keep, strict=True) if k], dtype=np.int64)
    twin = arrays.edge_twin[eb]
    turn = (np.arange(len(ea)) % 5 == 1) & (twin >= 0)
    ea[turn] = twin[turn]  # some a U-turn at b's end away (a key of 50 m beyond their length)
    ea[::7] = eb[::7]  # some on one edge
    edge_len = arrays.edge_length_m
    ob = rng.uniform(0, 1, len(eb)) * edge_len[eb]
    oa = rng.uniform(0, 1, len(ea)) * edge_len[ea]
    tol = rng.choice([10.0, 20.0, 40.0, 80.0], len(ea))  # steps of different sigmas
    xy = np.zeros(len(ea))  # every pair near in the plane
    slot = np.full(arrays.n_edges, -1, dtype=np.int64)
    back, near, reach = held_behind(ea, eb, oa, ob, xy, xy, xy, xy, tol, edge_len, slot)
    routes = default_net.edge_routes(eb[near], ea[near], reach)
    held_across(back, near, ea, eb, oa, ob, edge_len, routes.distance_m, tol)
    # every pair on two edges routed, each with its own tolerance as the bound of its group
    apart = np.flatnonzero(ea != eb)
    assert 0 < len(near) < len(apart)
    every = default_net.edge_routes(eb[apart], ea[apart], tol[apart])
    expected = np.full(len(ea), np.inf)
    same = (ea == eb) & (ob <= oa) & (oa - ob <= tol)
    expected[same] = (oa - ob)[same]
    d = (edge_len[eb[apart]] - ob[apart]) + every.distance_m + oa[apart]
    expected[apart] = np.where(d <= tol[apart], d, np.inf)
    assert np.isfinite(expected).sum() > 10
    assert np.array_equal(back, expected)
    assert (slot == -1).all()
