"""Benchmark: the paper's frictional contact (relations) against the penalty and augmented
Lagrangian baselines (``formulation`` in [[contact]], parsolve/effects/contact_penalty.py).

Cases (the scenes of tests/effects/test_contact.py, from scripts/bench_scenes.py; one process):
  block   configs/contact_block_friction.toml: stick → partial slip → slip, 10 steps;
          analytic: the friction resultant is μN = 3 once the block slides
  wedge   the V-wedge of docs/contact.md §7, stick and slip side by side: exact field
  hertz   configs/contact_hertz_cylinder.toml (frictionless): Hertz's p0 and half-width
  box3d   the exact 3D sheared box (oblique shift, stick then slip), refined to 12×12×4 hex
  3D box  configs/contact_friction_3d.toml as shipped (no analytic field)
  ironing configs/contact_ironing_2d.toml (finite sliding; the penalty pairs again on the
          displaced mesh, the augmented Lagrangian refuses finite sliding: its input error is
          the table's answer)
Per run: global (Newton) iterations per step, wall time of the run, penetration, cone
violation, error against the analytic solution, failed (cut) steps; one line per case on the
baselines (converged, or why not). Then, for the relations form:
  - global iterations per step against refinement (cells 1×, 4×, 16×) of the 3D friction,
    Hertz (a contact zone forming from nothing, 160 to 640 surface cells) and ironing scenes
    (configs/contact_ironing_3d.toml too when it exists; --smoke: 1× only);
  - the time per iteration split into pairing, contact refresh (/timings/contact: the Newton's
    begin_step / refresh hooks), assembly, factorization, solve (in process: parsolve's
    functions wrapped for the run, PETSc's log events);
  - MUMPS' analysis across iterations (PETSc log events MatLUFactorSym / MatLUFactorNum): kept
    (parsolve) against redone at each iteration, on the 3D friction scene at 4× and 16×
    (--max-cells 4: 4× only);
  - finite sliding's spans: the 2D ironing (4×) and the 3D ironing with smaller search radii
    than the shipped ones: the operator's size, its rebuilds (spans made again), the time and
    the answer against the shipped radius's;
and contact detection (pairing) and the per-iteration contact update as the surface grows: the
relations form's friction refresh (states + dual values) against the penalty's nodal forces and
tangents.

    .venv/bin/python scripts/bench_friction.py [--quick | --smoke] [--max-cells 1|4|16]
        → table, scripts/results/bench_friction.md and bench_friction.png
        (--quick: smaller sizes, printed only; --smoke: the small cases and 1× scenes, files
        in a temporary folder, ~25 s)
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
from mpi4py import MPI

import bench_harness as bh
from bench_pairing import surface_2d, surface_3d  # (reused surfaces)
from bench_scenes import (G, LAM, friction_3d_scene, hertz_scene, ironing_2d_scene,
                          ironing_3d_scene, sheared_box_scene, wedge_mesh, wedge_scene)
from parsolve.contact import friction as fr
from parsolve.contact import references
from parsolve.contact.pairing import pair_nodes
from parsolve.contact.rows import friction_dual, normal_rows, tangent_rows
from parsolve.driver import run
from parsolve.effects.contact_penalty import PenaltyContact
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

ROOT = bh.ROOT

E, NU, MU = 1000.0, 0.3, 0.3
FORMULATIONS = [("relations", ""), ("penalty", 'formulation = "penalty"'),
                ("penalty ×100", 'formulation = "penalty"\npenalty = {big}'),
                ("AL", 'formulation = "augmented_lagrangian"')]


def add_keys(text: str, lines: str) -> str:
    """Add ``lines`` to every [[contact]] section (after its name) and drop [output]."""
    text = text.replace("[output]\nfile = ", "# file = ")
    if not lines:
        return text
    out = []
    for line in text.splitlines():
        out.append(line)
        if line.startswith("name = ") and out[-2:-1] == ["[[contact]]"]:
            out.append(lines)
    return "\n".join(out) + "\n"


def solve(text: str, work: Path, name: str) -> tuple[dict, float]:
    path = work / f"{name}.toml"
    path.write_text(text)
    try:
        model = build_model(load_scene(path), MPI.COMM_WORLD)
    except InputError as exc:   # e.g. a baseline that does not take a deformable master
        return {"status": f"input error: {exc}".replace(f"{work}/", "")}, 0.0
    t0 = time.perf_counter()
    try:
        run(MPI.COMM_WORLD, model, str(work / f"{name}.h5"), {}, None, log=lambda *a: None)
    except Exception as exc:  # a failed run is a result too
        print(f"  {name}: {exc}", flush=True)
    seconds = time.perf_counter() - t0
    with h5py.File(work / f"{name}.h5", "r") as f:
        res = {"status": str(f.attrs["status"]).replace(f"{work}/", "")}   # (no scratch path)
        f.visititems(lambda k, o: res.__setitem__(k, o[()]) if isinstance(o, h5py.Dataset) else None)
    return res, seconds


def contact_measures(res: dict, names: list[str], mu: float) -> tuple[float, float]:
    """(largest penetration, largest cone violation (|Rt| − μRn)/max μRn) over all steps."""
    pen, cone = 0.0, 0.0
    for n in names:
        gap = res[f"fields/{n}_gap"]
        pen = max(pen, float(-gap.min()))
        if mu > 0:
            rn = res[f"fields/{n}_normal_reaction"][..., 0]
            rt = np.linalg.norm(res[f"fields/{n}_tangential_reaction"], axis=-1)
            cone = max(cone, float((rt - mu * rn).max() / max(mu * rn.max(), 1e-300)))
    return pen, cone


# ----------------------------------------------------------------------------- cases


def case_block(work: Path):
    text = (ROOT / "configs" / "contact_block_friction.toml").read_text()

    def error(res, first):
        """No analytic field (the resultants N = pN and, sliding, T = μN hold to round-off in
        every formulation): the displacements against the relations form's at its steps."""
        keep = [int(np.argmin(np.abs(res["steps/time"] - t))) for t in first["steps/time"]]
        u, u_ref = res["fields/displacement"][keep], first["fields/displacement"]
        return float(np.abs(u - u_ref).max() / np.abs(u_ref).max())
    return "block 2D (8×4 quad)", text, ["base"], MU, error, 0.125


def _against_first(res, first):
    """No analytic field: the displacements against the relations form's at its steps."""
    keep = [int(np.argmin(np.abs(res["steps/time"] - t))) for t in first["steps/time"]]
    u, u_ref = res["fields/displacement"][keep], first["fields/displacement"]
    return float(np.abs(u - u_ref).max() / np.abs(u_ref).max())


def case_friction_3d(work: Path):
    """configs/contact_friction_3d.toml as shipped (no analytic field)."""
    return ("box 3D oblique shift (6×6×2 hex)", friction_3d_scene(1), ["base"], MU,
            _against_first, 1.0 / 6)


def case_ironing(work: Path):
    """configs/contact_ironing_2d.toml (finite sliding on a deformable slab)."""
    return ("ironing 2D (32×8 + 4×2 quad)", ironing_2d_scene(work, 1), ["ironing"], MU,
            _against_first, 0.125)


def case_wedge(work: Path):
    beta, kappa = np.pi / 4, -1e-3
    ref = references.wedge_stick_slip(LAM, G, beta, kappa)
    mesh = work / "wedge.msh"
    wedge_mesh(mesh, beta)
    text = wedge_scene(mesh, ref)

    def error(res, first):
        pts = res["mesh/points"]
        exact = np.array([t * ref.displacement(pts) for t in res["steps/time"]])
        return float(np.abs(res["fields/displacement"] - exact).max() / np.abs(exact).max())
    return "V-wedge 2D (stick and slip, exact)", text, ["one", "two"], ref.mu, error, 0.25


def case_hertz(work: Path):
    text = (ROOT / "configs" / "contact_hertz_cylinder.toml").read_text()

    def error(res, first):
        load = -res["relations/lift/multiplier"][-1].sum()   # the load P (λ: minus the reaction)
        ref = references.hertz_cylinder(load, 10.0, references.effective_modulus(E, NU))
        return abs(res["fields/indent_normal_reaction"][-1, :, 0].max() / (8.0 / 160) / ref.p0 - 1)
    return "Hertz cylinder 2D (160×40 quad)", text, ["indent"], 0.0, error, 0.05


def case_box(work: Path, n: int):
    p, height, t_star = 10.0, 0.5, 0.45
    e = np.array([2.0, 1.0]) / np.sqrt(5.0)
    delta_end = MU * p * height / G / t_star
    text = sheared_box_scene(delta_end, e, t_star, p, MU, "reaction", height)
    text = text.replace("nx = 3\nny = 3\nnz = 2", f"nx = {n}\nny = {n}\nnz = {max(2, n // 3)}")
    gz = -p / (LAM + 2 * G)

    def error(res, first):
        pts = res["mesh/points"]
        worst = 0.0
        for k, t in enumerate(res["steps/time"]):
            tau = min(G * delta_end * t / height, MU * p)
            slip = delta_end * t - height * tau / G
            exact = np.column_stack([np.outer(slip + tau / G * pts[:, 2], e), gz * pts[:, 2]])
            worst = max(worst, np.abs(res["fields/displacement"][k] - exact).max() / np.abs(exact).max())
        return worst
    return f"sheared box 3D ({n}×{n}×{max(2, n // 3)} hex, exact)", text, ["base"], MU, error, 1.0 / n


# ----------------------------------------------------------------------------- runs


def formulations_table(work: Path, quick: bool, smoke: bool = False) -> tuple[list[str], list[dict]]:
    if smoke:   # the smallest cases only: every formulation on a 2D and a 3D scene
        cases = [case_wedge(work), case_box(work, 3)]
    else:
        cases = [case_block(work), case_wedge(work), case_hertz(work),
                 case_box(work, 6 if quick else 12), case_friction_3d(work), case_ironing(work)]
    rows, records = [], []
    for label, text, names, mu, error, h in cases:
        big = 100 * 100 * E / h
        first = None
        for form, keys in FORMULATIONS:
            scene = add_keys(text, keys.format(big=f"{big:g}"))
            res, seconds = solve(scene, work, f"{label.split()[0]}_{form.split()[0]}_{len(rows)}")
            its = res.get("steps/iterations", np.zeros(0))
            cuts = int(np.sum(res.get("steps/cuts", 0)))
            ok = res["status"] == "complete"
            pen, cone = contact_measures(res, names, mu) if its.size else (np.nan, np.nan)
            umax = float(np.abs(res["fields/displacement"]).max()) if its.size else 1.0
            first = res if first is None else first      # the relations form's run
            err = error(res, first) if ok else np.nan
            rec = dict(case=label, form=form, steps=its.size, its_mean=float(its.mean()) if its.size else 0,
                       its_max=int(its.max()) if its.size else 0, its_total=int(its.sum()),
                       seconds=seconds, penetration=pen / umax, cone=cone, error=err, cuts=cuts,
                       status="ok" if ok else res["status"][:60], reason=res["status"])
            records.append(rec)
            row = (f"| {label} | {form} | {rec['steps']} | {rec['its_mean']:.1f} | {rec['its_max']} | "
                   f"{rec['its_total']} | {seconds:.2f} | {rec['penetration']:.1e} | "
                   f"{max(cone, 0.0):.1e} | {err:.1e} | {cuts} | {rec['status']} |")
            print(row, flush=True)
            rows.append(row)
    head = ["| case | formulation | steps saved | iterations / step (mean) | max | total | "
            "time (s) | penetration / max \\|u\\| | cone violation | error | failed (cut) steps "
            "| status |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    return head + rows, records


def baselines_summary(records: list[dict]) -> list[str]:
    """One line per case: which baselines converge, and why the others do not."""
    lines = []
    for case in dict.fromkeys(r["case"] for r in records):
        recs = [r for r in records if r["case"] == case and r["form"] != "relations"]
        ok = [r["form"] for r in recs if r["status"] == "ok"]
        cut = [f"{r['form']} after {r['cuts']} cut steps" for r in recs
               if r["status"] == "ok" and r["cuts"]]
        bad = [r for r in recs if r["status"] != "ok"]
        line = f"- {case}: " + (", ".join(ok) + " converge" if ok else "no baseline converges")
        line += f" ({'; '.join(cut)})" if cut else ""
        # the same reason once (the scene file's name apart), with the formulations it stops
        why = {r["form"]: re.sub(r"^(input error: )\S+\.toml: ", r"\1", " ".join(r["reason"].split()))
               for r in bad}
        line += "".join(f"; {', '.join(f for f in why if why[f] == w)}: {w}"
                        for w in dict.fromkeys(why.values()))
        lines.append(line + ".")
    return lines


def bare_penalty(pairing, mu: float, eps: float, dim: int, npoints: int) -> PenaltyContact:
    """The penalty effect's force and tangent kernels on a bare pairing (no mesh, no scene):
    the attributes PenaltyContact.forces and .node_tangents read, set by hand (one rank: its
    surface every node, its ``fetch`` of u the identity)."""
    eff = object.__new__(PenaltyContact)
    eff.pairing, eff.mesh = pairing, SimpleNamespace(dim=dim)
    eff.surface, eff.fetch = np.arange(npoints), np.ravel
    eff.gradients(pairing)   # the pairs' gap gradients and their tuples' places
    eff.eps_n = eff.eps_t = np.full(len(pairing), eps)
    eff.touch, eff.touching = 0.0, np.zeros(len(pairing), bool)   # the closed rule: none here

    class Spec:
        pass
    eff.spec = Spec()
    eff.spec.mu = mu
    return eff


def update_times(quick: bool, smoke: bool = False) -> tuple[list[str], list[tuple]]:
    """Pairing, rows, and the per-iteration contact update of each formulation, per surface."""
    sizes = {"2D": [1000, 4000, 16000, 64000] if not quick else [1000, 4000],
             "3D": [32, 64, 128, 256] if not quick else [32, 64]}
    if smoke:
        sizes = {"2D": [1000], "3D": [32]}
    rows, data = [], []
    for label, make in (("2D", surface_2d), ("3D", surface_3d)):
        for n in sizes[label]:
            mpts, facets, slave, ftype = make(n, False)
            pts = np.vstack([mpts, slave])
            slaves = np.arange(len(mpts), len(pts))
            best = np.full(4, np.inf)
            for _ in range(3):
                t0 = time.perf_counter()
                p = pair_nodes(pts, slaves, facets, ftype).only_paired()
                t1 = time.perf_counter()
                rows_n, rows_t = normal_rows(p), tangent_rows(p)
                t2 = time.perf_counter()
                # relations form, one refresh: states + slip directions + the dual's values
                m, dm1 = len(p), p.tangents.shape[1]
                rng = np.random.default_rng(0)
                rn, rt = rng.random(m), rng.normal(size=(m, dm1)) * 0.3
                direction = np.ones((m, dm1)) / np.sqrt(dm1)
                state = np.full(m, fr.STICK, dtype=np.int8)
                state, direction, _ = fr.friction_update(state, direction, np.ones(m, bool), rn, rt,
                                                         rng.normal(size=(m, dm1)), MU, "reaction")
                friction_dual(p, MU, direction)
                t3 = time.perf_counter()
                # penalty: nodal forces and consistent tangents (each Newton iteration)
                eff = bare_penalty(p, MU, 1e5, pts.shape[1], len(pts))
                u = rng.normal(size=pts.shape) * 1e-3
                zero = {"gT": np.zeros((m, dm1))}
                f = eff.forces(u, zero, np.zeros(m), np.zeros((m, dm1)))
                eff.node_tangents(f)
                t4 = time.perf_counter()
                best = np.minimum(best, [t1 - t0, t2 - t1, t3 - t2, t4 - t3])
            ns = len(slaves)
            data.append((label, ns, *best))
            row = (f"| {label} | {ns} | {best[0]:.4f} | {best[1]:.4f} | {best[2]:.4f} | {best[3]:.4f} | "
                   f"{1e6 * best[0] / ns:.1f} | {1e6 * best[2] / ns:.2f} | {1e6 * best[3] / ns:.2f} |")
            print(row, flush=True)
            rows.append(row)
    head = ["| surface | slave nodes | pairing (s) | rows (s) | relations refresh (s) | penalty forces "
            "+ tangents (s) | pairing µs/node | refresh µs/node | penalty µs/node |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    return head + rows, data


# ----------------------------------------------------------------------------- refinement


class PhaseClock:
    """Seconds spent in some functions during a run, in process: each is wrapped for the run
    and put back after (the benchmark's instrumentation; parsolve itself records
    /timings/factorization, solve and contact per step). A phase counts its outermost call."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._undo: list[tuple] = []
        self._depth: dict[str, int] = {}

    def wrap(self, owner, attr: str, phase: str, inside: str | None = None,
             timer=time.perf_counter) -> None:
        """Time ``owner.attr`` as ``phase`` (only its calls made within phase ``inside``;
        ``timer``: time.process_time for the CPU seconds of this process)."""
        if not hasattr(owner, attr):   # (a pairing function another version may not have)
            return
        orig = owner.__dict__.get(attr, getattr(owner, attr))
        func = orig.__func__ if isinstance(orig, staticmethod) else orig
        self.seconds.setdefault(phase, 0.0)

        def timed(*args, **kw):
            if inside is not None and not self._depth.get(inside, 0):
                return func(*args, **kw)
            self._depth[phase] = self._depth.get(phase, 0) + 1
            t0 = timer()
            try:
                return func(*args, **kw)
            finally:
                self._depth[phase] -= 1
                if self._depth[phase] == 0:
                    self.seconds[phase] += timer() - t0
        setattr(owner, attr, staticmethod(timed) if isinstance(orig, staticmethod) else timed)
        self._undo.append((owner, attr, orig))

    def restore(self) -> None:
        for owner, attr, orig in reversed(self._undo):
            setattr(owner, attr, orig)
        self._undo.clear()


def _pairing_and_assembly(clock: PhaseClock) -> None:
    """Pairing: the contact effect's pairing functions called from the Newton's contact hooks
    (the finite sliding's re-pairing at each step and iteration; not the first pairing, in
    build_model, nor any pairing for the output). Assembly: the element kernels (f_int and tangent of every
    effect) and the saddle operator's assembly."""
    from parsolve.effects import contact as contact_effect
    from parsolve.effects import contact_sliding
    from parsolve.solvers.policies import RelationPolicies
    from parsolve.solvers.problem import SaddleProblem
    from parsolve.solvers.system import SaddleSystem

    clock.wrap(RelationPolicies, "begin_hooks", "hooks")
    clock.wrap(RelationPolicies, "refresh_hooks", "hooks")
    for module in (contact_effect, contact_sliding):   # (the names each module calls)
        for name in ("pair_nodes", "pair_on", "mortar_pairing", "mortar_pairing_3d"):
            if hasattr(module, name):
                clock.wrap(module, name, "pairing", inside="hooks")
    clock.wrap(SaddleProblem, "form", "kernels")
    clock.wrap(SaddleSystem, "assemble", "operator")


FACTOR_EVENTS = ("MatLUFactorSym", "MatLUFactorNum", "MatCholFctrSym", "MatCholFctrNum")


def _events() -> dict[str, tuple[int, float]]:
    """(count, seconds) of PETSc's factorization log events so far (this process)."""
    from petsc4py import PETSc

    out = {}
    for name in FACTOR_EVENTS:
        info = PETSc.Log.Event(name).getPerfInfo()
        out[name] = (int(info["count"]), float(info["time"]))
    return out


def instrumented(text: str, work: Path, name: str, extra=None) -> dict:
    """One run in process with the phases timed; ``extra(clock)``: more wrappers."""
    clock = PhaseClock()
    _pairing_and_assembly(clock)
    if extra is not None:
        extra(clock)
    from parsolve.solvers.linear import LinearSolver   # (after ``extra``: its version timed)
    clock.wrap(LinearSolver, "_prepare", "factorization_cpu", timer=time.process_time)
    ev0, cpu0 = _events(), time.process_time()
    try:
        res, seconds = solve(text, work, name)
    finally:
        clock.restore()
    cpu = time.process_time() - cpu0
    ev1 = _events()
    d = {k: (ev1[k][0] - ev0[k][0], ev1[k][1] - ev0[k][1]) for k in FACTOR_EVENTS}
    its = np.asarray(res.get("steps/iterations", np.zeros(0, int)))

    def timing(key):
        return float(np.sum(res[f"timings/{key}"])) if f"timings/{key}" in res else np.nan
    # the hooks' time as parsolve records it (/timings/contact), else as timed here
    contact = timing("contact") if "timings/contact" in res else clock.seconds["hooks"]
    return dict(status=res["status"], iterations=its, cuts=int(np.sum(res.get("steps/cuts", 0))),
                wall=seconds, cpu=cpu, pairing=clock.seconds["pairing"],
                refresh=contact - clock.seconds["pairing"], kernels=clock.seconds["kernels"],
                operator=clock.seconds["operator"],
                factorization=timing("factorization"), solve=timing("solve"),
                analyses=d["MatLUFactorSym"][0] + d["MatCholFctrSym"][0],
                numeric=d["MatLUFactorNum"][0] + d["MatCholFctrNum"][0],
                analysis_s=d["MatLUFactorSym"][1] + d["MatCholFctrSym"][1],
                numeric_s=d["MatLUFactorNum"][1] + d["MatCholFctrNum"][1],
                factorization_cpu=clock.seconds["factorization_cpu"],
                u=res.get("fields/displacement"), res=res)


def refinement_cases(work: Path, factors: list[int]) -> list[tuple[str, int, str]]:
    """(scene, refinement in cells, scene text): the shipped 3D friction, Hertz (a zone
    forming from nothing: 160, 320, 640 surface cells) and ironing scenes, their surface's
    cells × factor along each direction (cells × factor²); the 3D ironing when configs/ has
    it."""
    cases = [("3D friction (contact_friction_3d)", f * f, friction_3d_scene(f)) for f in factors]
    cases += [("Hertz 2D, zone from nothing (contact_hertz_cylinder)", f * f, hertz_scene(f))
              for f in factors]
    cases += [("ironing 2D (contact_ironing_2d)", f * f, ironing_2d_scene(work, f)) for f in factors]
    for f in factors:
        text = ironing_3d_scene(f)
        if text is not None:
            cases.append(("ironing 3D (contact_ironing_3d)", f * f, text))
    return cases


def refinement_tables(work: Path, factors: list[int]) -> tuple[list[str], list[str], list[dict]]:
    """Global iterations per step against refinement, and the time split per iteration."""
    its_rows, split_rows, records = [], [], []
    for label, cells, text in refinement_cases(work, factors):
        r = instrumented(text, work, f"refine_{len(records)}")
        r.update(case=label, cells=cells)
        records.append(r)
        its = r["iterations"]
        ok = r["status"] == "complete"
        status = "ok" if ok else " ".join(r["status"].split())
        its_rows.append(f"| {label} | {cells}× | {its.size} | {its.max() if its.size else '-'} | "
                        f"{its.mean() if its.size else float('nan'):.1f} | {int(its.sum())} | "
                        f"{r['cuts']} | {' '.join(map(str, its))} | {r['wall']:.2f} | {r['cpu']:.2f} | "
                        f"{status} |")
        n = max(r["numeric"], 1)   # linear solves: Newton iterations, failed attempts included
        phases = [r[k] for k in ("pairing", "refresh", "kernels", "operator", "factorization",
                                 "solve")]
        other = r["wall"] - sum(p for p in phases if np.isfinite(p))
        split_rows.append(f"| {label} | {cells}× | {r['numeric']} | "
                          + " | ".join(f"{1e3 * p / n:.2f}" for p in phases + [other])
                          + f" | {1e3 * r['wall'] / n:.2f} |")
        print(its_rows[-1], flush=True)
        print(split_rows[-1], flush=True)
    its_head = ["| scene | cells | steps | max iterations / step | mean | total | failed (cut) "
                "steps | per step | time (s) | CPU (s) | status |",
                "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---|"]
    split_head = ["| scene | cells | linear solves | pairing | contact refresh | assembly: "
                  "kernels | assembly: operator | factorization | solve | other | total "
                  "(ms / iteration) |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    return its_head + its_rows, split_head + split_rows, records


def _reanalyse(clock: PhaseClock) -> None:
    """For comparison: the KSP reset before every factorization whose operator changed, so
    that MUMPS analyses again (what a solver rebuilt at each iteration would pay)."""
    from parsolve.solvers.linear import LinearSolver

    orig = LinearSolver._prepare

    def prepare(self):
        mat = self.ksp.getOperators()[0]
        if self._state is not None and mat.stateGet() != self._state:
            self._restart(mat)
        return orig(self)
    LinearSolver._prepare = prepare
    clock._undo.append((LinearSolver, "_prepare", orig))


def mumps_table(work: Path, factors: list[int]) -> list[str]:
    """The analysis (symbolic factorization) kept across iterations, as parsolve does, against
    redone at every iteration: counts and times from PETSc's log events, and this process's
    CPU seconds in the factorizations (less sensitive than clock time to the other jobs of a
    shared machine). The saving: one analysis per factorization but the first."""
    rows = []
    for f in factors:
        text = friction_3d_scene(f)
        kept = instrumented(text, work, f"mumps_kept_{f}")
        redone = instrumented(text, work, f"mumps_redone_{f}", _reanalyse)
        same = (float(np.abs(kept["u"] - redone["u"]).max() / np.abs(kept["u"]).max())
                if kept["u"] is not None and redone["u"] is not None
                and kept["u"].shape == redone["u"].shape else np.nan)
        for how, r in (("kept (parsolve)", kept), ("redone each iteration", redone)):
            n = max(r["numeric"], 1)
            rows.append(f"| 3D friction {f * f}× | {how} | {r['numeric']} | {r['analyses']} | "
                        f"{1e3 * r['analysis_s'] / max(r['analyses'], 1):.2f} | "
                        f"{1e3 * r['numeric_s'] / n:.2f} | {1e3 * r['factorization'] / n:.2f} | "
                        f"{1e3 * r['factorization_cpu'] / n:.2f} | {r['wall']:.2f} | {same:.1e} |")
            print(rows[-1], flush=True)
        # what the reuse saves, in CPU (the clock times follow the machine's other jobs)
        c_kept, c_redone = (r["factorization_cpu"] / max(r["numeric"], 1) for r in (kept, redone))
        rows.append(f"| 3D friction {f * f}× | saved by the reuse | | | | | | "
                    f"{1e3 * (c_redone - c_kept):.2f} per iteration "
                    f"({100 * (1 - c_kept / max(c_redone, 1e-300)):.0f} %) | | |")
    head = ["| scene | MUMPS analysis | factorizations | analyses | ms / analysis | ms / numeric "
            "factorization | factorization ms / iteration | factorization CPU ms / iteration | "
            "time (s) | max \\|Δu\\| / max \\|u\\| between the two |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    return head + rows


def _operator_sizes(sizes: list[int]):
    """An ``instrumented`` extra: the operator's stored nonzeros at each factorization."""
    def extra(clock: PhaseClock) -> None:
        from parsolve.solvers.linear import LinearSolver

        orig = LinearSolver._prepare

        def prepare(self):
            sizes.append(int(self.ksp.getOperators()[0].getInfo()["nz_used"]))
            return orig(self)
        LinearSolver._prepare = prepare
        clock._undo.append((LinearSolver, "_prepare", orig))
    return extra


def span_cases(work: Path, smoke: bool) -> list[tuple[str, float, list[float], str]]:
    """(scene, its shipped search_radius, the radii tried, scene text): the 2D ironing at 4×
    (facets 0.0625; smoke: 1×, 0.125) and the shipped 3D ironing (faces 0.125)."""
    f = 1 if smoke else 2
    cases = [(f"ironing 2D ({f * f}×)", 1.6, [0.2, 1.6] if smoke else [0.1, 0.2, 0.4, 1.6],
              ironing_2d_scene(work, f))]
    text = None if smoke else ironing_3d_scene(1)
    if text is not None:
        cases.append(("ironing 3D (1×)", 0.7, [0.15, 0.3, 0.7], text))
    return cases


def span_table(work: Path, smoke: bool) -> list[str]:
    """Finite sliding's spans: a smaller search_radius, a smaller operator pattern (fewer
    master nodes per row) made again more often (each time: the operator built again and
    MUMPS' analysis redone). Each radius against the shipped one's answer."""
    rows = []
    for label, shipped_radius, radii, text in span_cases(work, smoke):
        runs = {}
        for radius in radii:
            sizes: list[int] = []
            scene = re.sub(r"search_radius = [0-9.eE+-]+", f"search_radius = {radius}", text)
            r = instrumented(scene, work, f"span_{len(rows)}_{radius}", _operator_sizes(sizes))
            r["nnz"] = (min(sizes), max(sizes)) if sizes else (0, 0)
            runs[radius] = r
        ref = runs[shipped_radius]["u"]
        for radius, r in runs.items():
            same = (float(np.abs(r["u"] - ref).max() / np.abs(ref).max())
                    if r["u"] is not None and ref is not None and r["u"].shape == ref.shape
                    else np.nan)
            n = max(r["numeric"], 1)
            pattern = float(np.sum(r["res"].get("timings/pattern", 0.0)))
            status = "ok" if r["status"] == "complete" else " ".join(r["status"].split())
            nnz = f"{r['nnz'][0]}–{r['nnz'][1]}" if r["nnz"][0] != r["nnz"][1] else r["nnz"][0]
            rows.append(f"| {label} | {radius:g}{' (shipped)' if radius == shipped_radius else ''}"
                        f" | {nnz} | {r['analyses'] - 1} | {int(r['iterations'].sum())} | "
                        f"{1e3 * pattern:.1f} | {1e3 * r['analysis_s'] / max(r['analyses'], 1):.2f}"
                        f" | {1e3 * r['numeric_s'] / n:.2f} | {r['wall']:.2f} | {r['cpu']:.2f} | "
                        f"{same:.1e} | {status} |")
            print(rows[-1], flush=True)
    head = ["| scene | search_radius | operator nonzeros | patterns made again | iterations | "
            "pattern (ms, run) | ms / analysis | ms / numeric factorization | time (s) | "
            "CPU (s) | max \\|Δu\\| / max \\|u\\| against the shipped radius | status |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    return head + rows


def picture(records: list[dict], data: list[tuple], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in records))
    forms = [f for f, _ in FORMULATIONS]
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    width = 0.8 / len(forms)
    x = np.arange(len(cases))
    for k, form in enumerate(forms):
        recs = [next(r for r in records if r["case"] == c and r["form"] == form) for c in cases]
        axes[0].bar(x + k * width, [r["its_total"] for r in recs], width, label=form)
        axes[1].bar(x + k * width, [max(r["error"], 1e-16) if np.isfinite(r["error"]) else 1.0
                                    for r in recs], width, label=form)
    for ax, title in ((axes[0], "total Newton iterations"), (axes[1], "error vs analytic")):
        ax.set_xticks(x + 0.4 - width / 2, [c.split(" (")[0] for c in cases], rotation=15)
        ax.set_title(title)
    axes[1].set_yscale("log")
    axes[0].legend()
    for label, marker in (("2D", "o"), ("3D", "s")):
        pts = [d for d in data if d[0] == label]
        ns = np.array([d[1] for d in pts])
        for col, name in ((2, "pairing"), (4, "relations refresh"), (5, "penalty forces+tangents")):
            axes[2].loglog(ns, [d[col] / d[1] * 1e6 for d in pts], marker=marker, label=f"{label} {name}")
    axes[2].set_xlabel("slave nodes")
    axes[2].set_ylabel("µs per slave node")
    axes[2].set_title("contact detection and update per node")
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    from petsc4py import PETSc

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller 3D box and surfaces; no files")
    ap.add_argument("--max-cells", type=int, default=16, choices=(1, 4, 16),
                    help="largest refinement in cells of the refinement and MUMPS tables "
                         "(default 16: 1×, 4×, 16×; 4 on a loaded machine)")
    bh.add_smoke(ap)
    args = ap.parse_args(argv)
    quick, smoke = args.quick or args.smoke, args.smoke
    PETSc.Log.begin()   # the factorization events' counts (MUMPS analysis reuse)
    load0 = bh.machine_info()["loadavg_start"]
    top = {1: 1, 4: 2, 16: 4}[1 if smoke else min(args.max_cells, 4 if quick else 16)]
    refine = [f for f in (1, 2, 4) if f <= top]
    with tempfile.TemporaryDirectory() as tmp:
        table, records = formulations_table(Path(tmp), quick, smoke)
        its_table, split_table, _ = refinement_tables(Path(tmp), refine)
        mumps = mumps_table(Path(tmp), [f for f in refine if f > 1] or [1])
        spans = span_table(Path(tmp), smoke)
    upd, data = update_times(quick, smoke)
    load1 = bh.machine_info()["loadavg_start"]
    text = ("# Frictional contact: relations (the paper's) against penalty and augmented Lagrangian\n\n"
            f"`scripts/bench_friction.py`{' --smoke' if smoke else ''}, one process, direct "
            f"solver (MUMPS), {bh.utc_now()} UTC, {bh.load_line(load0, load1)} "
            f"({bh.machine_info()['cpus']} cores shared with other jobs: times are indicative). "
            "penalty: default "
            "100 E/h per unit area; penalty ×100: 10⁴ E/h; AL: Uzawa augmentations on the default "
            "penalty, tolerance 1e-6. Iterations: global Newton iterations per saved step (AL: "
            "augmentations included); failed steps were cut in two and retried by the driver (the iterations of failed attempts are not recorded in the result file and not counted here; the time includes them). "
            "Penetration: largest −gap over the largest |u|; cone violation: max(|Rt| − μRn) / "
            "max μRn; error: block, 3D oblique box and ironing, the displacements against the relations form's (no analytic field; "
            "N = pN and, sliding, T = μN hold to round-off in every formulation); wedge and box, the displacement field against the exact one (max norm, "
            "relative); Hertz, the peak nodal pressure against p0.\n\n"
            + "\n".join(table) + "\n\nBaselines, case by case:\n\n"
            + "\n".join(baselines_summary(records))
            + "\n\n## Global iterations against refinement\n\n"
            "The relations form on the shipped scenes refined in cells: configs/contact_friction_3d.toml "
            f"with nx, ny × {', '.join(map(str, refine))} (nz = 2 kept: the contact surface "
            f"refined, cells × {', '.join(str(f * f) for f in refine)}"
            f"{'' if top == 4 or smoke else '; this run: --max-cells ' + str(top * top) + ', the larger sizes not run'}); "
            "configs/contact_hertz_cylinder.toml with nx, ny × the same factors (160 surface "
            "cells at 1×: the contact zone forms from nothing in its one step); "
            "configs/contact_ironing_2d.toml on a generated equivalent of its .msh "
            "(`scripts/make_ironing_2d_mesh.py`, the shipped file's generator at 1×), the "
            "slab's and the die's quads × the same factors along x and y; configs/contact_ironing_3d.toml "
            "the same way when it exists (a mesh file: 1× only). Per step: the global iterations "
            "of each saved step.\n\n" + "\n".join(its_table)
            + "\n\n## Time per iteration\n\n"
            "Milliseconds (clock) per linear solve (one per Newton iteration, failed attempts included), same runs "
            "(clock times on a loaded machine: compare the CPU column above for the whole run). "
            "pairing: the contact effect's pairing functions inside the Newton (finite sliding's "
            "re-pairing at each step and iteration; the first pairing, at set-up, is not counted); "
            "contact refresh: the effects' begin_step / refresh hooks (`/timings/contact`) less "
            "their pairing; assembly: the element kernels (f_int and tangent of every effect) "
            "and the saddle operator's assembly from them; factorization and solve: `/timings/factorization`, `solve` "
            "(MUMPS); other: the rest of the run (active set, residuals, output).\n\n"
            + "\n".join(split_table)
            + "\n\n## MUMPS analysis across iterations\n\n"
            "Counts of PETSc's log events MatLUFactorSym / MatCholFctrSym (analyses) and "
            "MatLUFactorNum / MatCholFctrNum (numeric factorizations) over a run of the 3D "
            "friction scene. parsolve keeps one KSP and one operator whose pattern does not "
            "change (values rewritten in place; finite sliding's spans made again are the "
            "exception, next section), so PCSetUp sees SAME_NONZERO_PATTERN and "
            "factors numerically only: one analysis per run. 'redone each iteration': the KSP "
            "reset before every factorization, for comparison (the same answer: last column). "
            "ms / analysis, ms / numeric factorization: the events' clock times; factorization "
            "ms / iteration: `/timings/factorization` over the factorizations (the analysis, the "
            "numeric factorization and MUMPS' copy of the matrix); CPU: this process's CPU "
            "seconds in them, the measure to compare on a shared machine.\n\n" + "\n".join(mumps)
            + "\n\n## Finite sliding: the spans' size\n\n"
            "Each finite-sliding row spans the master nodes of the facets within `search_radius` "
            "of the slave when its span was made; when a slave nears its span's edge the spans are made "
            "again around it and the operator built again on the new pattern (MUMPS analyses "
            "it once). A smaller radius: a smaller pattern (operator nonzeros: the smallest "
            "and largest over the run), made again more often (patterns made again: the "
            "analyses less the first; pattern: `/timings/pattern`, the operator's rebuilds). "
            "The answer does not depend on it (last column but one: the displacements against "
            "the shipped radius's run). The 2D ironing refined 4× (facets 0.0625) and the "
            "shipped 3D ironing (faces 0.125).\n\n" + "\n".join(spans)
            + "\n\n## Contact detection and update as the surface grows\n\n"
            "Curved surfaces of `bench_pairing.py` (linear facets), best of 3. 'relations refresh': "
            "one friction_update + the frictional dual's values (what the relations form does "
            "between iterations); 'penalty': the nodal forces and consistent tangents (what the "
            "baselines do at every iteration).\n\n" + "\n".join(upd) + "\n")
    if not quick or smoke:   # smoke: into the harness's temporary folder
        out = bh.publish("bench_friction.md", text)
        picture(records, data, out.with_suffix(".png"))
        print(f"written {out} and {out.with_suffix('.png')}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
