"""Multi-body scenes: graspcore (1 and 2 threads) beside MuJoCo and PyBullet (issue 3, item 7).

Runs in .venv. The scenes are bench/bench_scenes.py's (`scene_spec(name)`, built here
with its `build_world`); MuJoCo and PyBullet rebuild them from the same numbers in their
workers (bench/scenes_mujoco.py + bench/multibody_mujoco.py, bench/scenes_pybullet.py,
both in .venv-bench). bench/run_bench.py calls `run_all` with the two workers and puts
`report_section` into docs/benchmarks.md.

Protocol per scene: every engine builds the scene and runs the same warm-up
(spec["warmup_s"]); then `repeats` timed repeats of `steps` steps, engines interleaved
within each repeat, each engine continuing its own simulation (no resets), so every
engine covers the same simulated time. The positions of all dynamic bodies at the start
and the end of the timed window give the drift.

`profile(name)` samples graspcore's step with `perf record` (call graphs from DWARF; the
shared library has debug info) over the timed window only and splits the step into the
phases of gc_world_step (xFCA, velocities, contact detection, chain solve, positions).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

import bench_scenes as bs  # noqa: E402
from multibody_spec import held_bodies  # noqa: E402

MJ_VARIANTS = ("recommended", "recommended+noslip", "condim3")
MJ_MAIN = "recommended"
THREADS = (1, 2)
TABLE_HALF_XY = bs.TABLE_HALF[0]


def log(msg: str) -> None:
    print(f"[bench] {msg}", file=sys.stderr, flush=True)


def stats(samples: list[float]) -> dict:
    q = np.percentile(samples, [25, 50, 75])
    return {"median": float(q[1]), "p25": float(q[0]), "p75": float(q[2]), "min": float(min(samples)),
            "n": len(samples)}


def motion(spec: dict, p0, p1) -> dict:
    """Drift of the dynamic bodies between two position lists (spec order, statics left out)."""
    dyn = [i for i, b in enumerate(spec["bodies"]) if not b["static"]]
    held = set(held_bodies(spec))
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = np.linalg.norm(p1 - p0, axis=1)
    hi = [k for k, i in enumerate(dyn) if i in held]
    oi = [k for k, i in enumerate(dyn) if i not in held]
    off = int(np.sum((np.abs(p1[:, :2]) > TABLE_HALF_XY).any(axis=1) | (p1[:, 2] < -0.01)))
    return {"held_m": float(d[hi].max()) if hi else None,
            "others_m": float(d[oi].max()) if oi else None,
            "others_median_m": float(np.median(d[oi])) if oi else None,
            "moved_1mm": int(np.sum(d > 1e-3)), "off_table": off, "bodies": len(dyn)}


def _ours_positions(w, spec) -> list:
    poses = np.asarray(w.body_poses)
    return [poses[i, :3].tolist() for i, b in enumerate(spec["bodies"]) if not b["static"]]


def run_scene(name: str, mj, pb, steps: int, repeats: int) -> dict:
    spec = bs.scene_spec(name)
    dt = spec["dt"]
    warm = int(round(spec.get("warmup_s", 0.0) / dt))
    worlds = {}
    for t in THREADS:
        w, bodies, fingers = bs.build_world(spec, threads=t)
        w.step(dt, steps=warm)
        worlds[t] = (w, fingers, _ours_positions(w, spec))
    mj_p0, pb_p0 = {}, None
    if mj:
        for v in MJ_VARIANTS:
            mj_p0[v] = mj(cmd="mb_setup", key=f"{name}/{v}", spec=spec, variant=v)["positions"]
    if pb:
        pb_p0 = pb(cmd="setup", key=name, spec=spec)["positions"]
    times = {f"ours{t}": [] for t in THREADS}
    times.update({f"mj:{v}": [] for v in MJ_VARIANTS} if mj else {})
    if pb:
        times["pybullet"] = []
    ncon = {}
    for r in range(repeats):
        for t in THREADS:
            w = worlds[t][0]
            t0 = time.perf_counter()
            w.step(dt, steps=steps)
            times[f"ours{t}"].append((time.perf_counter() - t0) / steps)
        if mj:
            for v in MJ_VARIANTS:
                rep = mj(cmd="mb_time", key=f"{name}/{v}", steps=steps)
                times[f"mj:{v}"].append(rep["per_step"])
                ncon[f"mj:{v}"] = rep["ncon"]
        if pb:
            rep = pb(cmd="time", key=name, steps=steps)
            times["pybullet"].append(rep["per_step"])
            ncon["pybullet"] = rep["ncon"]
    row = {"name": name, "spec": spec, "steps": steps, "repeats": repeats, "sim_s": steps * repeats * dt,
           "bodies": sum(1 for b in spec["bodies"] if not b["static"]), "fingers": len(spec["fingers"]),
           "times": {k: stats(v) for k, v in times.items()}, "motion": {}, "ncon": ncon}
    for t in THREADS:
        w, fingers, p0 = worlds[t]
        row["motion"][f"ours{t}"] = motion(spec, p0, _ours_positions(w, spec))
        row[f"ours{t}_hash"] = w.state_hash()
    w, fingers, _ = worlds[1]
    row["ncon"]["ours"] = len(w.contacts())
    row["chains"] = w.chain_count()
    row["finger_states"] = [w.finger_state(f) for f in fingers]
    if mj:
        row["mj_warnings"] = {}
        for v in MJ_VARIANTS:
            rep = mj(cmd="mb_positions", key=f"{name}/{v}")
            row["motion"][f"mj:{v}"] = motion(spec, mj_p0[v], rep["positions"])
            row["mj_warnings"][v] = rep["warnings"]
            mj(cmd="mb_drop", key=f"{name}/{v}")
    if pb:
        rep = pb(cmd="positions", key=name)
        row["motion"]["pybullet"] = motion(spec, pb_p0, rep["positions"])
        pb(cmd="drop", key=name)
    msg = f"{name}: ours {row['times']['ours1']['median'] * 1e6:.1f} / {row['times']['ours2']['median'] * 1e6:.1f} us"
    if mj:
        msg += f", MuJoCo {row['times']['mj:' + MJ_MAIN]['median'] * 1e6:.1f} us"
    if pb:
        msg += f", PyBullet {row['times']['pybullet']['median'] * 1e6:.1f} us"
    log(msg)
    return row


def scene_steps(name: str, quick: bool) -> int:
    big = name == "100-body pile"
    return (50 if big else 200) if quick else (300 if big else 1000)


def run_all(mj, pb, quick: bool = False) -> list[dict]:
    repeats = 3 if quick else 15
    return [run_scene(name, mj, pb, scene_steps(name, quick), repeats) for name in bs.SCENES]


def initial_overlaps(spec: dict) -> dict:
    """Contact points of the scene as built, before any step (graspcore's detection with
    a zero-length step would move things; use one 1 ns step): count and deepest."""
    w, _, _ = bs.build_world(spec)
    w.step(1e-9)
    seps = [c["separation"] for c in w.contacts()]
    deep = [s for s in seps if s < -1e-3]
    return {"penetrating_1mm": len(deep), "deepest_m": float(-min(seps)) if seps else 0.0}


# --- profile ---------------------------------------------------------------------------
PHASES = [("xFCA (fingers)", "gc_xfca_update"),
          ("velocities (gravity, finger coupling, effective-mass factors)", "gc_dynamics_velocities"),
          ("contact detection (broad + narrow phase, manifolds, chains)", "gc_contacts_detect"),
          ("  of which GJK/EPA (gc_collide)", "gc_collide"),
          ("contact solve (chains, PGS + position pass)", "gc_contacts_solve"),
          ("positions", "gc_dynamics_positions")]


def _profile_child(name: str, steps: int, ctl: str, ack: str) -> int:
    """Runs under `perf record -D -1 --control fifo:ctl,ack`: warm up with sampling off,
    then sample the timed window only."""
    spec = bs.scene_spec(name)
    w, _, _ = bs.build_world(spec, threads=1)
    w.step(spec["dt"], steps=int(round(spec.get("warmup_s", 0.0) / spec["dt"])))
    with open(ctl, "w") as c:
        c.write("enable\n")
    with open(ack) as a:
        a.readline()
    w.step(spec["dt"], steps=steps)
    with open(ctl, "w") as c:
        c.write("disable\n")
    with open(ack) as a:
        a.readline()
    return 0


def profile(name: str, steps: int) -> dict:
    """Share of gc_world_step per phase (inclusive samples), threads=1. {'error': ...}
    when perf is missing or not permitted."""
    perf = shutil.which("perf")
    if not perf:
        return {"error": "`perf` is not installed"}
    with tempfile.TemporaryDirectory() as tmp:
        ctl, ack, data = (os.path.join(tmp, n) for n in ("ctl", "ack", "perf.data"))
        os.mkfifo(ctl)
        os.mkfifo(ack)
        cmd = [perf, "record", "-q", "-e", "cpu-clock", "-F", "2000", "--call-graph", "dwarf,16384",
               "-D", "-1", f"--control=fifo:{ctl},{ack}", "-o", data, "--",
               sys.executable, os.path.abspath(__file__), "--profile-child", name, str(steps), ctl, ack]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        except subprocess.TimeoutExpired:
            return {"error": "perf record timed out"}
        if r.returncode != 0 or not os.path.exists(data):
            return {"error": "perf record failed: " + (r.stderr.strip().splitlines() or ["?"])[-1]}
        rep = subprocess.run([perf, "report", "-i", data, "--children", "--sort", "symbol", "--stdio",
                              "-g", "none"], capture_output=True, text=True, timeout=300)
    incl: dict[str, float] = {}
    pat = re.compile(r"^\s*([\d.]+)%\s+([\d.]+)%\s+\[\.\]\s+(\S+)(\s+\(inlined\))?")
    samples = re.search(r"# Samples: (\S+)", rep.stdout)
    for line in rep.stdout.splitlines():
        m = pat.match(line)
        if m and not m.group(4) and m.group(3) not in incl:   # first line of a symbol: its total
            incl[m.group(3)] = float(m.group(1))
    total = incl.get("gc_world_step")
    if not total:
        return {"error": "no samples in gc_world_step (perf report: "
                         + (rep.stderr.strip().splitlines() or ["?"])[-1] + ")"}
    # Normalise by the sum of the five top-level phases, not by gc_world_step: a sample
    # whose DWARF unwinding stopped short of gc_world_step still names its phase.
    top = sum(incl.get(sym, 0.0) for label, sym in PHASES if not label.startswith(" ")) or total
    return {"phases": [(label, incl.get(sym, 0.0) / top) for label, sym in PHASES],
            "samples": samples.group(1) if samples else "?", "step_share": total / 100.0}


def profile_all(rows: list[dict], quick: bool = False) -> dict:
    """Each scene sampled over ~1.5 s of stepping (0.3 s with --quick)."""
    out = {}
    for r in rows:
        name = r["name"]
        log(f"profile: {name}")
        steps = int((0.3 if quick else 1.5) / max(r["times"]["ours1"]["median"], 1e-6))
        out[name] = profile(name, max(100, steps))
        out[name]["steps"] = max(100, steps)
        if "error" in out[name]:
            log(f"profile unavailable: {out[name]['error']}")
            break
    return out


# --- report ------------------------------------------------------------------------------
def us(x: float) -> str:
    return f"{x * 1e6:.1f}"


def dist(x) -> str:
    if x is None:
        return "–"
    x *= 1e6
    if x < 1e-3:
        return "0" if x == 0 else f"{x:.0e} µm"
    if x < 1000:
        return f"{x:.3g} µm"
    if x < 1e6:
        return f"{x / 1000:.3g} mm"
    return f"{x / 1e6:.3g} m"


def target_rows(rows: list[dict], have_mj: bool) -> list[str]:
    out = []
    for r in rows:
        if not have_mj:
            out.append(f"| Step time ≤ 0.5× MuJoCo, {r['name']} | MuJoCo not run | **not measured** |")
            continue
        m = r["times"]["mj:" + MJ_MAIN]["median"]
        r1, r2 = r["times"]["ours1"]["median"] / m, r["times"]["ours2"]["median"] / m
        out.append(f"| Step time ≤ 0.5× MuJoCo, {r['name']} | {r1:.2f}× with 1 thread, {r2:.2f}× with 2 "
                   f"({us(r['times']['ours1']['median'])} / {us(r['times']['ours2']['median'])} vs "
                   f"{us(m)} µs) | {'**met**' if r1 <= 0.5 else '**MISSED**'} |")
    return out


def report_section(rows, mjinfo, pbinfo, prof, overlaps, xml_small: str, pb_error: str = "") -> str:
    L = []
    add = L.append
    have_mj, have_pb = mjinfo is not None, pbinfo is not None
    add("## Multi-body scenes: graspcore, MuJoCo and PyBullet (dt = 1 ms)")
    add("")
    add("The four scenes of `bench/bench_scenes.py`, built from the same `scene_spec()` numbers in "
        "each engine (models below). Each engine runs the scene's warm-up, then "
        f"{rows[0]['repeats']} timed repeats; a repeat is {rows[0]['steps']} steps "
        f"({rows[-1]['steps']} for the pile) per engine, engines interleaved within each repeat, each "
        "continuing its own simulation. Median (25th–75th percentile) time per step. graspcore and "
        "MuJoCo step N times inside C (`w.step(dt, steps=N)`, `mj_step(m, d, nstep=N)`); PyBullet has "
        "no multi-step call, so its figure includes one Python call per step "
        + (f"({pbinfo['empty_step_s'] * 1e6:.2f} µs on an empty world)" if have_pb else "") + ". "
        "MuJoCo and PyBullet are single-threaded; graspcore is shown with `threads=1` and `threads=2` "
        "(the target is judged with 1 thread: like for like).")
    add("")
    add("| Scene | bodies + fingers | contacts (ours / MuJoCo / PyBullet) | graspcore 1 thread µs | "
        "graspcore 2 threads µs | MuJoCo µs | MuJoCo +noslip µs | MuJoCo condim 3 µs | PyBullet µs | "
        "ours/MuJoCo (1 t / 2 t) | ours/MuJoCo +noslip (1 t) | ours/PyBullet (1 t / 2 t) |")
    add("|---|---|---|---|---|---|---|---|---|---|---|---|")

    def cell(r, k):
        t = r["times"].get(k)
        return f"{us(t['median'])} ({us(t['p25'])}–{us(t['p75'])})" if t else "–"

    for r in rows:
        o1, o2 = r["times"]["ours1"]["median"], r["times"]["ours2"]["median"]
        m = r["times"].get("mj:" + MJ_MAIN)
        p = r["times"].get("pybullet")
        rm = f"**{o1 / m['median']:.2f}×** / {o2 / m['median']:.2f}×" if m else "–"
        rp = f"**{o1 / p['median']:.2f}×** / {o2 / p['median']:.2f}×" if p else "–"
        mn = r["times"].get("mj:recommended+noslip")
        rn = f"{o1 / mn['median']:.2f}×" if mn else "–"
        con = f"{r['ncon']['ours']} / {r['ncon'].get('mj:' + MJ_MAIN, '–')} / {r['ncon'].get('pybullet', '–')}"
        add(f"| {r['name']} | {r['bodies']} + {r['fingers']} | {con} | {cell(r, 'ours1')} | {cell(r, 'ours2')} | "
            f"{cell(r, 'mj:' + MJ_MAIN)} | {cell(r, 'mj:recommended+noslip')} | {cell(r, 'mj:condim3')} | "
            f"{cell(r, 'pybullet')} | {rm} | {rn} | {rp} |")
    add("")
    add("Contacts: graspcore's contact points (body–body, fingers not counted: they are xFCA god-objects), "
        "MuJoCo's `ncon` (finger contacts included), PyBullet's `getContactPoints()` (finger contacts "
        "included), at the end of the run. graspcore 1 and 2 threads ended in the same state in every "
        "scene: " + ", ".join(f"{r['name']} {'yes' if r['ours1_hash'] == r['ours2_hash'] else '**NO**'}"
                               for r in rows) + " (`state_hash()`).")
    add("")

    add("### Do the simulations work? Drift over the timed window")
    add("")
    add("Largest displacement of a held body (the fingers' box or tray) and of any other body between the "
        "start and the end of the timed window (the time span in the first column), and how many bodies "
        "moved more than 1 mm or ended off the table. A held or resting scene should not move; the pile "
        "is timed after its warm-up and may still be settling.")
    add("")
    engines = [("ours1", "graspcore")]
    if have_mj:
        engines += [(f"mj:{v}", f"MuJoCo {v}") for v in MJ_VARIANTS]
    if have_pb:
        engines.append(("pybullet", "PyBullet"))
    add("| Scene (timed span) | engine | held body moved | other bodies: largest / median move | "
        "bodies moved > 1 mm | bodies off the table |")
    add("|---|---|---|---|---|---|")
    for r in rows:
        for k, label in engines:
            mo = r["motion"][k]
            add(f"| {r['name']} ({r['sim_s']:.1f} s) | {label} | {dist(mo['held_m'])} | "
                f"{dist(mo['others_m'])} / {dist(mo['others_median_m'])} | {mo['moved_1mm']} of {mo['bodies']} | "
                f"{mo['off_table']} |")
    add("")
    add("graspcore's fingers at the end: " + "; ".join(
        f"{r['name']}: {'/'.join(r['finger_states']) or 'none'}" for r in rows if r["finger_states"]) + ".")
    slid = [f"{label} in *{r['name']}* ({dist(r['motion'][k]['held_m'])})" for r in rows
            for k, label in engines if (r["motion"][k]["held_m"] or 0) > 1e-3]
    if slid:
        add("Held bodies that slid more than 1 mm in the fingers over the timed window (so that engine "
            "timed a grasp that is not holding; 50 mm for the tray means it slid down onto the table): "
            + "; ".join(slid) + ".")
    if have_mj and any(any(w.values()) for r in rows for w in r.get("mj_warnings", {}).values()):
        add("MuJoCo warnings: " + "; ".join(f"{r['name']} {v}: {w}" for r in rows
                                            for v, w in r.get("mj_warnings", {}).items() if w) + ".")
    pile = overlaps.get("100-body pile")
    if pile and pile["penetrating_1mm"] > 0:
        add("")
        add(f"**The pile starts with interpenetrating boxes**: as built, graspcore finds "
            f"{pile['penetrating_1mm']} contact points deeper than 1 mm (deepest {pile['deepest_m'] * 1e3:.1f} mm). "
            "graspcore pushes such overlaps apart at a capped 0.2 m/s (split impulse); MuJoCo's soft "
            "contacts and Bullet push them apart much harder, and bodies that get launched off the table "
            "fall for the rest of the run (column *off the table*): those engines then time a smaller pile.")
    elif pile:
        add("")
        add("The pile starts with no overlaps (4 layers of 5 x 5 boxes, 6 cm apart): as built, graspcore finds "
            f"no contact point deeper than 1 mm (deepest {pile['deepest_m'] * 1e3:.1f} mm), so every engine drops "
            "the same 100 boxes.")
    add("")

    add("### The models")
    add("")
    add("- **Bodies**: every body is a box with the spec's half extents, mass, pose and friction; the table is "
        "static. Inertia is that of a uniform-density box in all three engines.")
    add("- **Friction**: all touching pairs in these scenes have equal friction, so the combination rules "
        "agree: graspcore's geometric mean; MuJoCo's maximum (fingertip geoms have friction 0, so a finger "
        "takes the touched body's µ, as in graspcore); Bullet multiplies, so each PyBullet body gets "
        "`lateralFriction = sqrt(µs)` (the product is then exactly the geometric mean). µs is used "
        "throughout (MuJoCo and Bullet have one friction coefficient).")
    add("- **MuJoCo** (`bench/multibody_mujoco.py`), the conventions of the grasp model above: each "
        "fingertip a 10 g sphere body on three slide joints with `position` actuators, kp = the finger's "
        "stiffness, kv = its damping (1000 N/m, 2 N s/m; the tray's pinch 4000 N/m, 5 N s/m), control = "
        "the HIP, `gravcomp=1`, starting where it touches the face; `cone=\"elliptic\"`, `impratio=\"10\"`, "
        "`integrator=\"implicitfast\"`, Newton solver with default iterations and tolerance, every geom "
        "`condim=\"4\"`, friction `µs 0.005 0.0001`, `solref=\"0.002 1\"`, default `solimp`. The quoted "
        "ratio uses this configuration. *MuJoCo +noslip* adds `noslip_iterations=\"10\"`, MuJoCo's remedy "
        "for the slip of its soft contacts (see the drift table: without it MuJoCo's grasps slide). *MuJoCo condim 3* gives box–box and box–table contacts "
        "`condim=\"3\"` (no torsional friction, which graspcore's contacts do not model per point either: "
        "a face contact's torsion comes from its several points), fingertips keep condim 4; it is shown "
        "so that the reader can see how much that choice matters.")
    if have_pb:
        pr = pbinfo["params"]
        add(f"- **PyBullet** {pbinfo['pybullet']} (`bench/scenes_pybullet.py`): `DIRECT`, boxes as "
            "`GEOM_BOX` rigid bodies (`useMaximalCoordinates=True`), the table with mass 0; timestep 1 ms, "
            f"one `stepSimulation()` per step, every engine parameter at PyBullet's default "
            f"(read back: {pr['numSolverIterations']} solver iterations). Each fingertip is a "
            "10 g sphere (its 0.1 N weight carried by the constraint) held at its HIP by a `JOINT_FIXED` constraint to the world with maxForce = stiffness "
            "× squeeze (3 N for 1000 N/m × 3 mm, 16 N for the tray's 4000 N/m × 4 mm): PyBullet's Python API "
            "has no spring constraint, so the finger is a force-limited position constraint that pushes "
            "into the face with the force the graspcore spring has at that squeeze and holds the other "
            "directions (a held, static grasp is the same; a moving HIP would not be). Not "
            "`JOINT_POINT2POINT`: it leaves the sphere free to spin and the pinched box rolls down the "
            "spinning fingertips (we measured it falling). The fingertips are Bullet multibody bases "
            "(`createConstraint` to the world fails on a maximal-coordinate body).")
    else:
        add(f"- **PyBullet**: not run ({pb_error or 'unavailable'}).")
    if xml_small:
        add("")
        add("<details><summary>Generated MJCF, 5 boxes + 5 fingers</summary>")
        add("")
        add("```xml")
        add(xml_small.strip())
        add("```")
        add("")
        add("</details>")
    add("")

    add("### Where graspcore's multi-body step time goes")
    add("")
    first = next(iter(prof.values()), None) if prof else None
    if not prof or (first and "error" in first):
        add(f"Not profiled in this run: {first['error'] if first else 'skipped'}.")
    else:
        add("`perf record` (cpu-clock, 2 kHz, DWARF call graphs) of each scene with `threads=1`, sampling "
            "only steps after the warm-up (about 1.5 s of stepping per scene, a separate process after the "
            "timing). Inclusive samples per phase of `gc_world_step` (docs/solver.md) as a share of the "
            "five phases together, and that share of the measured 1-thread median in µs.")
        add("")
        names = list(prof)
        add("| Phase | " + " | ".join(names) + " |")
        add("|---|" + "---|" * len(names))
        med = {r["name"]: r["times"]["ours1"]["median"] for r in rows}
        for k, (label, _) in enumerate(PHASES):
            cells = []
            for n in names:
                share = prof[n]["phases"][k][1]
                cells.append(f"{share * 100:.0f} % ({share * med.get(n, 0) * 1e6:.1f} µs)")
            add(f"| {label} | " + " | ".join(cells) + " |")
        add("| samples | " + " | ".join(str(prof[n]["samples"]) for n in names) + " |")
    add("")
    return "\n".join(L)


if __name__ == "__main__":
    if len(sys.argv) == 6 and sys.argv[1] == "--profile-child":
        sys.exit(_profile_child(sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]))
    print(__doc__)
