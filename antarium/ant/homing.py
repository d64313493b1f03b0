"""Path-integration experiments of the virtual ant in the emulated dome (Stone et al. 2017's foraging task; Zhang's
vector-memory and CXMB trips, Mitchell 2019 section 2.5).

Foraging task: from the nest at the origin the ant walks a random outbound route (a correlated random walk of
`n_outbound` decisions driven from outside, its CX integrating what the ball and the compass tell it), then homes
by its CX for `n_inbound` decisions. Metrics (Stone 2017): closest approach to the nest as a share of the outbound
path length; tortuosity of the homeward path, tau = L / C after Stone 2017 but read at the closest approach: L
(m) the length of the whole homeward path from the feeder to the closest approach (any loops walked before it
included), C (m) how much nearer the nest the ant is there than at the feeder (feeder-to-nest distance minus the
closest approach); 1 = a straight approach, NaN when the ant never came nearer than the feeder (Stone 2017 reads
C after a path as long as the feeder distance instead); the search around the nest (median distance from the nest
after the closest approach, as a share of the outbound path).

A trip on which the compass loses its cue (the sky compass reads no polarised sky, e.g. with the ant inside or
against a cylinder that hides the dorsal rim) ends there: `Trip.lost_cue` says at which decision and why, its
metrics cover the decisions walked until then, and the experiment goes on with its next trip or seed.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from antarium.ant.central_complex import CentralComplex
from antarium.ant.compass import NoSkyCueError
from antarium.ant.eye import EyeParams
from antarium.ant.metrics import json_text, median_mad
from antarium.plots.homing import plot_arena, plot_distance, plot_trips

#: turning of the outbound random walk: turn_k = 0.9 turn_(k-1) + N(0, sd) rad per decision
OUTBOUND_TURN_SD = 0.02
OUTBOUND_TURN_MEMORY = 0.9
#: the foraging task's scene: the dome's sky (the sun, the polarised UV pixels) and nothing else
PI_SCENE = "sky"
FACE_SIZE = 64
#: a learning trip home ends its learning where the ant first comes this close (m) to the nest: the inbound route
#: ends at the nest, and the search loops around it (views facing every way) are not part of it
NEST_RADIUS = 0.1


def write_json(path: Path, record: Any) -> None:
    """`record` as strict JSON text (`json_text`) in `path`."""
    path.write_text(json_text(record))


#: frames an ant of the foraging task stands still at most waiting for its sky compass cue (`VirtualAnt`): in the
#: fixed tether the polarisers settle within about 16 frames of a 57 deg turn; in free_yaw the dome never turns
CUE_WAIT_FRAMES = 60

#: frames the polarisers get to come to rest before an experiment (they reach it in about 150, at 190 Hz)
SETTLE_FRAMES = 400


def settle(ant) -> None:
    """Run frames until the polarisers rest exactly (two frames with the same angles, at most SETTLE_FRAMES):
    until then they still turn towards the sky's e-vectors by ever smaller amounts, and a trip would start from
    a dome that depends on how many frames ran before it (the trials before it); RuntimeError if they do not."""
    angles = None
    for _ in range(SETTLE_FRAMES):
        ant.frame()
        now = ant.read_polarisers()
        if angles is not None and np.array_equal(now, angles):
            return
        angles = now
    raise RuntimeError(f"the polarisers did not come to rest within {SETTLE_FRAMES} frames")


def trip_decisions(n_outbound: int, n_inbound: int | None) -> tuple[int, int]:
    """(outbound, inbound) decisions of a task, the inbound trip as long as the outbound one when None; one
    ValueError unless outbound >= 2 (the first decision only sets the heading) and inbound >= 1 integers."""
    n_inbound = n_outbound if n_inbound is None else n_inbound
    for name, n, least in (("outbound", n_outbound, 2), ("inbound", n_inbound, 1)):
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < least:
            raise ValueError(f"{name} decisions must be an integer >= {least}, got {n!r}")
    return int(n_outbound), int(n_inbound)


def outbound_turns(seed: int, n: int) -> np.ndarray:
    """(n,) turns (rad) of a seeded correlated random walk, the first turn a random initial heading."""
    rng = np.random.default_rng(seed)
    turns = np.empty(n)
    turn = 0.0
    for k in range(n):
        turn = OUTBOUND_TURN_MEMORY * turn + rng.normal(0.0, OUTBOUND_TURN_SD)
        turns[k] = turn
    turns[0] = rng.uniform(-math.pi, math.pi)
    return turns


@dataclass
class Trip:
    """Positions xy (n, 2) (world, m), headings (n,) rad and model traces of one trip's decisions; lost_cue: why
    the trip ended early ("decision k: ..." when the compass lost its cue), None when it walked every decision."""

    xy: np.ndarray
    heading: np.ndarray
    traces: list[dict[str, float]]
    lost_cue: str | None = None

    @classmethod
    def walked(cls, xy: list, heading: list, traces: list, lost: NoSkyCueError | None = None) -> Trip:
        """The trip of the decisions recorded; `lost`: the error that ended it after len(traces) decisions."""
        why = None if lost is None else f"decision {len(traces)}: {lost}"
        return cls(np.asarray(xy, np.float64).reshape(-1, 2), np.asarray(heading, np.float64), traces, why)


@dataclass
class HomingOutcome:
    seed: int
    compass: str
    model: str
    outbound_length_m: float
    feeder_distance_m: float
    closest_approach_m: float
    closest_approach_share: float
    tortuosity: float
    search_median_share: float
    decisions_per_s: float
    lost_cue: str | None = None


def _record(ant, xy: list, heading: list) -> None:
    xy.append(ant.position)
    heading.append(ant.heading)


def walk_outbound(ant, turns: np.ndarray, step: float) -> Trip:
    """Walk the outbound route from the nest (origin) while the model only integrates (`observe`)."""
    ant.place(0.0, 0.0, float(turns[0]))
    xy, heading, traces = [], [], []
    ant.frame()
    ant.sense()  # the baseline of the distance walked
    try:
        for turn in turns[1:]:
            ant.act(step, float(turn))
            ant.frame()
            traces.append(ant.model.observe(ant.sense()))
            _record(ant, xy, heading)
    except NoSkyCueError as e:
        return Trip.walked(xy, heading, traces, e)
    return Trip.walked(xy, heading, traces)


def walk_home(ant, n: int, learning: bool = False) -> Trip:
    """Let the model steer for `n` decisions; `learning`: its MBONs learn (`model.learning`) until the ant first
    comes within NEST_RADIUS of the nest (the origin), and not after."""
    xy, heading, traces = [], [], []
    if learning:
        ant.model.learning = True
    try:
        for _ in range(n):
            cmd = ant.decide()
            traces.append(cmd.trace)
            _record(ant, xy, heading)
            if learning and math.hypot(*ant.position) < NEST_RADIUS:
                ant.model.learning = learning = False
    except NoSkyCueError as e:
        return Trip.walked(xy, heading, traces, e)
    finally:
        if learning:
            ant.model.learning = False
    return Trip.walked(xy, heading, traces)


def path_length(xy: np.ndarray, start=(0.0, 0.0)) -> float:
    """Length (m) of the path from `start` through the positions xy (n, 2) m."""
    return float(np.linalg.norm(np.diff(np.vstack([start, xy]), axis=0), axis=1).sum())


def homing_metrics(outbound: Trip, inbound: Trip, nest=(0.0, 0.0)) -> dict[str, float]:
    """Closest approach (m, share of the outbound length), tortuosity and search spread of a homeward trip, over
    the feeder and the decisions it walked (a trip that lost its cue at once stays at the feeder's distance).
    Tortuosity: L / C (after Stone 2017, read at the closest approach): L the length (m) of the whole homeward
    path from the feeder to the closest approach, loops before it included; C how much nearer (m) the nest the ant
    is there than at the feeder; NaN when it never came nearer (its closest approach is the feeder)."""
    length = path_length(outbound.xy, nest)
    start = outbound.xy[-1]
    feeder = float(np.hypot(*(start - nest)))
    path = np.vstack([start, inbound.xy])
    dist = np.hypot(*(path - nest).T)
    k = int(np.argmin(dist))
    path = path[:k + 1]
    homeward = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    approach = float(dist[0] - dist[k])  # > 0 whenever k > 0: argmin takes the first of equal distances
    tortuosity = homeward / approach if k > 0 and approach > 0 else math.nan
    return {"outbound_length_m": length, "feeder_distance_m": feeder, "closest_approach_m": float(dist[k]),
            "closest_approach_share": float(dist[k] / length), "tortuosity": tortuosity,
            "search_median_share": float(np.median(dist[k:]) / length)}


def check_compass(model_params: dict | None, compass: str) -> None:
    """Refuse a model parameter `compass` other than the task's: the model and the rig would read different
    compasses (and the files carry the task's name)."""
    given = (model_params or {}).get("compass", compass)
    if given != compass:
        raise ValueError(f"model parameter compass={given!r} differs from the task's compass {compass!r}; "
                         f"choose the compass with --compass (sky or ideal), not --param compass")


def trial_cx(params, seed: int) -> CentralComplex:
    """A fresh CX for trial `seed` of a model with `params` (`CXModelParams`): its noise stream seeded from
    (params.seed, seed), so that a trial walks the same whichever trials ran before it (bit for bit, once the
    experiment let the polarisers come to rest: `settle`)."""
    stream = int(np.random.SeedSequence([params.seed, seed]).generate_state(1)[0])
    return CentralComplex(replace(params.cx(), seed=stream))


def pi_trial(ant, seed: int, n_outbound: int, n_inbound: int) -> tuple[dict[str, float], Trip, Trip]:
    """One foraging trip: a fresh CX (memory and noise stream, `trial_cx`), outbound, homing; (metrics, outbound,
    inbound). The metrics carry `lost_cue` ("outbound/inbound, decision k: why") when the compass lost its cue;
    after an outbound that lost it the ant does not home (metrics NaN)."""
    ant.model.cx = trial_cx(ant.model.params, seed)
    outbound = walk_outbound(ant, outbound_turns(seed, n_outbound), ant.model.params.step)
    if outbound.lost_cue is not None:
        nan = dict.fromkeys(("outbound_length_m", "feeder_distance_m", "closest_approach_m", "closest_approach_share",
                             "tortuosity", "search_median_share"), math.nan)
        return {**nan, "lost_cue": f"outbound, {outbound.lost_cue}"}, outbound, Trip.walked([], [], [])
    inbound = walk_home(ant, n_inbound)
    lost = None if inbound.lost_cue is None else f"inbound, {inbound.lost_cue}"
    return {**homing_metrics(outbound, inbound), "lost_cue": lost}, outbound, inbound


def pi_homing(out_dir: str | Path | None, seeds=range(20), n_outbound: int = 1500, n_inbound: int | None = None,
              compass: str = "sky", model_params: dict | None = None, scene: Any = PI_SCENE,
              echo=None, tether: str = "free_yaw", cue_wait_frames: int = CUE_WAIT_FRAMES) -> dict[str, Any]:
    """Stone 2017's foraging task for each seed, in the emulated dome; returns (and writes to `out_dir`:
    `pi_homing_<compass>.json`, `_paths.png`, `_distance.png`) the outcomes and their medians. tether: the
    loop's ("fixed": the scene and its sky turn with the ant); cue_wait_frames: see `VirtualAnt`."""
    from antarium.ant.models import make_model
    from antarium.ant.world import virtual_rig

    n_outbound, n_inbound = trip_decisions(n_outbound, n_inbound)
    check_compass(model_params, compass)
    if tether not in ("free_yaw", "fixed") or isinstance(cue_wait_frames, bool) \
            or not isinstance(cue_wait_frames, int) or cue_wait_frames < 0:
        raise ValueError(f"tether must be free_yaw or fixed and cue_wait_frames an integer >= 0, got {tether!r} "
                         f"and {cue_wait_frames!r}")
    model = make_model("cx", EyeParams().n_pn, **{"compass": compass, **(model_params or {})})
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:  # an unwritable folder is found before the run, not after it
        out.mkdir(parents=True, exist_ok=True)
    outcomes: list[HomingOutcome] = []
    trips: dict[str, tuple[Trip, Trip]] = {}
    with virtual_rig(model, scene=scene, eye_params=None, renderer_kwargs={"face_size": FACE_SIZE},
                     compass=compass, tether=tether, cue_wait_frames=cue_wait_frames) as ant:
        settle(ant)
        for seed in seeds:
            t0 = time.perf_counter()
            metrics, outbound, home = pi_trial(ant, seed, n_outbound, n_inbound)
            rate = (n_outbound + n_inbound) / (time.perf_counter() - t0)
            outcomes.append(HomingOutcome(seed, compass, "cx", decisions_per_s=rate, **metrics))
            trips[f"seed {seed}"] = (outbound, home)
            if echo is not None:
                lost = f"; ended without a compass cue: {metrics['lost_cue']}" if metrics["lost_cue"] else ""
                echo(f"seed {seed} ({compass} compass): closest approach {100 * metrics['closest_approach_share']:.2f}"
                     f" % of {metrics['outbound_length_m']:.1f} m, tortuosity {metrics['tortuosity']:.2f}{lost}")
    summary = summarise(outcomes)
    if out is not None:
        title = (f"CX path integration, {compass} compass, {tether.replace('_', ' ')} tether ({len(outcomes)} "
                 f"routes of {n_outbound} steps)")
        summary["paths_png"] = str(plot_trips(out / f"pi_homing_{compass}_paths.png", trips, title))
        summary["distance_png"] = str(plot_distance(out / f"pi_homing_{compass}_distance.png", trips, title,
                                                    model.params.step))
        write_json(out / f"pi_homing_{compass}.json",
                   {"summary": summary, "outcomes": [asdict(o) for o in outcomes], "n_outbound": n_outbound,
                    "n_inbound": n_inbound, "scene": str(scene), "tether": tether,
                    "cue_wait_frames": cue_wait_frames})
    return summary


def summarise(outcomes: list[HomingOutcome]) -> dict[str, Any]:
    """Medians over the runs that reached the feeder (NaN metrics left out); the runs whose compass lost its cue."""
    share = median_mad([o.closest_approach_share for o in outcomes])
    return {"runs": len(outcomes), "compass": outcomes[0].compass if outcomes else None,
            "closest_approach_share_median": share[0], "closest_approach_share_mad": share[1],
            "within_5_percent": sum(o.closest_approach_share <= 0.05 for o in outcomes),
            "tortuosity_median": median_mad([o.tortuosity for o in outcomes])[0],
            "search_median_share": median_mad([o.search_median_share for o in outcomes])[0],
            "decisions_per_s_closed_loop": float(np.median([o.decisions_per_s for o in outcomes])),
            "runs_without_cue": {f"seed {o.seed}": o.lost_cue for o in outcomes if o.lost_cue}}


def walk_outbound_avoiding(ant, turns: np.ndarray, step: float) -> Trip:
    """Like `walk_outbound`, with the model's optic-flow avoidance turn added to each turn of the random walk."""
    ant.place(0.0, 0.0, float(turns[0]))
    xy, heading, traces = [], [], []
    ant.frame()
    ant.sense()
    try:
        for turn in turns[1:]:
            ant.frame()
            senses = ant.sense()
            trace = ant.model.observe(senses)
            flow_turn, flow_trace = ant.model.avoidance(senses)
            traces.append({**trace, **flow_trace})
            _record(ant, xy, heading)
            ant.act(step, float(np.clip(turn + flow_turn, -ant.model.params.max_turn, ant.model.params.max_turn)))
    except NoSkyCueError as e:
        return Trip.walked(xy, heading, traces, e)
    return Trip.walked(xy, heading, traces)


#: the arena's homeward trips: (name, the MBONs learn, steer with the MBONs), in the order they are walked
ARENA_HOME_TRIPS = (("cx", True, False), ("cxmb", False, True), ("cx_again", False, False))


@dataclass
class ArenaOutcome:
    seed: int
    compass: str
    outbound_length_m: float
    collisions_outbound: int
    collisions_cx: int
    collisions_cxmb: int
    collisions_cx_again: int
    closest_cx_share: float
    closest_cxmb_share: float
    closest_cx_again_share: float
    learned_views: int
    lost_cue: dict[str, str]      # trip name -> why it ended early (no compass cue); empty when none did


def arena_trial(ant, clutter, seed: int, n_outbound: int, n_inbound: int):
    """Mitchell 2019's seed task with a CXMB ant (avoiding by optic flow throughout): outbound through the clutter;
    home by the CX while the MBONs learn (trip 1, until the ant reaches the nest); back at the feeder with the
    outbound memory restored, home by CXMB (trip 2); and again by the CX alone (trip 2, comparison). Every trip home
    starts from the same state: the ant put down at the feeder (no optic flow carried over) and the CX as it was
    there, its CPU4 memory (Zhang's copied memory), TB1 and its noise stream, so that the trips differ only by what
    steers them (common random numbers: the CX-alone trip walks trip 1 again, and CXMB's difference to it is the
    MBONs'). An outbound trip that lost its compass cue ends the seed (no feeder to home from: NaN shares).
    Returns (ArenaOutcome, trips)."""
    model = ant.model
    model.cx.reset()
    out = walk_outbound_avoiding(ant, outbound_turns(seed, n_outbound), model.params.step)
    trips = {"outbound": out}
    if out.lost_cue is None:
        at_feeder = copy.deepcopy(model.cx)
        feeder, feeder_heading = out.xy[-1], float(out.heading[-1])
        for name, learning, use_mbons in ARENA_HOME_TRIPS:
            ant.place(float(feeder[0]), float(feeder[1]), feeder_heading)  # the first time too: no flow carried over
            ant.frame()
            ant.sense()
            model.cx = copy.deepcopy(at_feeder)
            model.use_mbons = use_mbons
            trips[name] = walk_home(ant, n_inbound, learning)
    home = [name for name, _, _ in ARENA_HOME_TRIPS]
    close = {k: homing_metrics(out, trips[k])["closest_approach_share"] if k in trips else math.nan for k in home}
    length = path_length(out.xy)
    hits = {k: clutter.collisions(trips[k].xy) if k in trips else 0 for k in ("outbound", *home)}
    outcome = ArenaOutcome(seed, model.params.compass, length, hits["outbound"], hits["cx"], hits["cxmb"],
                           hits["cx_again"], close["cx"], close["cxmb"], close["cx_again"], model.learned_views,
                           {k: t.lost_cue for k, t in trips.items() if t.lost_cue is not None})
    return outcome, trips


def summarise_arena(outcomes: list[ArenaOutcome], compass: str) -> dict[str, Any]:
    """Medians of the closest approaches (over the seeds that reached the feeder), runs without a collision, and
    the trips that ended without a compass cue."""
    return {
        "runs": len(outcomes), "compass": compass,
        **{f"closest_{name}_share_median": median_mad([getattr(o, f"closest_{name}_share") for o in outcomes])[0]
           for name, _, _ in ARENA_HOME_TRIPS},
        "runs_without_collision": sum(o.collisions_outbound + o.collisions_cx + o.collisions_cxmb
                                      + o.collisions_cx_again == 0 for o in outcomes),
        "trips_without_cue": {f"seed {o.seed}": o.lost_cue for o in outcomes if o.lost_cue},
    }


def cluttered_arena(out_dir, seeds=range(20), n_outbound: int = 1500, n_inbound: int | None = None,
                    compass: str = "sky", kind: str = "cxmb", model_params: dict | None = None, echo=None,
                    arena: dict | None = None, sky: dict | None = None) -> dict[str, Any]:
    """The seed's cluttered-arena task for each seed (a fresh arena and a fresh model per seed); writes
    `arena_<compass>.json` and one picture per seed into `out_dir` (when given); returns the summary.
    arena: `make_clutter` parameters; sky: the "sky" scene's parameters (default: the default sky)."""
    from antarium.ant.clutter import clutter_scene, make_clutter
    from antarium.ant.models import make_model
    from antarium.ant.world import virtual_rig

    n_outbound, n_inbound = trip_decisions(n_outbound, n_inbound)
    check_compass(model_params, compass)
    outcomes: list[ArenaOutcome] = []
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        clutter = make_clutter(seed, **(arena or {}))
        model = make_model(kind, EyeParams().n_pn, **{"compass": compass, "avoid": True, "seed": seed,
                                                      **(model_params or {})})
        with virtual_rig(model, scene=clutter_scene(clutter, sky), renderer_kwargs={"face_size": FACE_SIZE},
                         compass=compass) as ant:
            settle(ant)
            outcome, trips = arena_trial(ant, clutter, seed, n_outbound, n_inbound)
        outcomes.append(outcome)
        if out is not None:
            plot_arena(out / f"arena_{compass}_seed{seed:02d}.png", clutter, trips,
                       f"cluttered arena, seed {seed} ({compass} compass)", kind)
        if echo is not None:
            lost = "".join(f"; {name} trip ended without a compass cue at {why}"
                           for name, why in outcome.lost_cue.items())
            echo(f"arena seed {seed}: closest CX {100 * outcome.closest_cx_share:.2f} %, {kind} "
                 f"{100 * outcome.closest_cxmb_share:.2f} %, CX again {100 * outcome.closest_cx_again_share:.2f} %; "
                 f"collisions out {outcome.collisions_outbound}, CX {outcome.collisions_cx}, {kind} "
                 f"{outcome.collisions_cxmb}{lost}")
    summary = summarise_arena(outcomes, compass)
    if out is not None:
        write_json(out / f"arena_{compass}.json",
                   {"summary": summary, "outcomes": [asdict(o) for o in outcomes], "n_outbound": n_outbound,
                    "n_inbound": n_inbound, "model": kind})
    return summary


def displacement(out_dir, seed: int = 0, n_outbound: int = 600, n_inbound: int | None = None,
                 lateral: float = 0.5, ks=(1.0, 0.8, 0.5, 0.0), compass: str = "sky", scene: Any = "habitat",
                 echo=None) -> dict[str, Any]:
    """PI against visual memory: a CXMB ant walks out (random walk), homes once by its CX while its MBONs learn the
    homeward views, and is then put down `lateral` m to the left of the feeder with its outbound memory restored.
    PI points to a fictive nest displaced as far; the views point back to the learned route. For each k (CPU4's
    weight; 1 = PI alone, 0 = the MBONs alone) the ant homes again; reports its closest approach to the real and
    to the fictive nest (m, over the decisions walked; NaN for a trip that lost its compass cue at its first) and
    why a trip ended early (`lost_cue`, None when it walked every decision). Writes `displacement_<compass>.json`
    and `.png` into `out_dir` (when given). ValueError, before anything runs, for a lateral that is not finite, and
    when the outbound walk loses its compass cue (no feeder to displace the ant from)."""
    from antarium.ant.models import make_model
    from antarium.ant.world import virtual_rig

    n_outbound, n_inbound = trip_decisions(n_outbound, n_inbound)
    if isinstance(lateral, bool) or not isinstance(lateral, int | float | np.floating) or not math.isfinite(lateral):
        raise ValueError(f"lateral displacement must be a finite number of metres (left of the feeder; negative: "
                         f"right), got {lateral!r}")
    path = Path(out_dir) if out_dir is not None else None
    if path is not None:  # an unwritable folder is found before the run, not after it
        path.mkdir(parents=True, exist_ok=True)
    model = make_model("cxmb", EyeParams().n_pn, compass=compass, seed=seed)
    trips: dict[str, Trip] = {}
    result: dict[str, Any] = {"seed": seed, "lateral_m": lateral, "compass": compass, "runs": {}}
    with virtual_rig(model, scene=scene, renderer_kwargs={"face_size": FACE_SIZE}, compass=compass) as ant:
        settle(ant)
        model.cx.reset()
        out = walk_outbound(ant, outbound_turns(seed, n_outbound), model.params.step)
        if out.lost_cue is not None:
            raise ValueError(f"displacement: the outbound walk ended without a compass cue at {out.lost_cue}; "
                             f"no feeder to displace the ant from (scene {scene!r} needs a polarised sky, or use "
                             f"the ideal compass)")
        memory = model.home_memory()
        model.use_mbons = False  # home by the CX, also after the MBONs stop learning at the nest
        trips["home 1: CX, MBONs learn"] = home = walk_home(ant, n_inbound, learning=True)
        result["home_1_lost_cue"] = home.lost_cue
        model.use_mbons = True
        fx, fy = out.xy[-1]
        h = float(out.heading[-1])
        left = np.array([-math.sin(h), math.cos(h)])
        start = np.array([fx, fy]) + lateral * left
        fictive = lateral * left
        result["fictive_nest_xy_m"] = [float(fictive[0]), float(fictive[1])]
        for k in ks:
            ant.place(float(start[0]), float(start[1]), h)
            ant.frame()
            ant.sense()
            model.restore(memory)
            model.params = type(model.params)(**{**asdict(model.params), "k": k})
            trip = walk_home(ant, n_inbound)
            trips[f"displaced, k = {k}"] = trip
            run = result["runs"][str(k)] = {
                "closest_to_nest_m": _closest(trip.xy, (0.0, 0.0)),
                "closest_to_fictive_nest_m": _closest(trip.xy, fictive), "lost_cue": trip.lost_cue}
            if echo is not None:
                lost = f"; ended without a compass cue at {trip.lost_cue}" if trip.lost_cue else ""
                echo(f"k = {k}: closest to nest {run['closest_to_nest_m']:.2f} m, to the fictive "
                     f"nest {run['closest_to_fictive_nest_m']:.2f} m{lost}")
    if path is not None:
        pictures = {name: (out, trip) for name, trip in trips.items()}
        result["png"] = str(plot_trips(path / f"displacement_{compass}.png", pictures,
                                       f"displaced {lateral} m left of the feeder: PI vs visual memory",
                                       {"fictive nest (where PI points)": tuple(result["fictive_nest_xy_m"])},
                                       {f"displaced, k = {k}": (float(start[0]), float(start[1])) for k in ks}))
        write_json(path / f"displacement_{compass}.json", result)
    return result


def _closest(xy: np.ndarray, point) -> float:
    """Closest distance (m) of the positions xy (n, 2) m to `point` (x, y) m; NaN when there are none."""
    return float(np.hypot(*(xy - np.asarray(point, np.float64)).T).min()) if len(xy) else math.nan
