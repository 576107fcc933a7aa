"""CPU time of ``orbit.numerical``, in process (no bus): each acceleration term, and one RK4 step.

    python benchmarks/bench_orbit_numerical.py [--steps 2000] [--repeat 3]

Rows: one evaluation of each term's ``acceleration`` (point mass; harmonics to 2 x 0, 6 x 0,
20 x 20; Sun and Moon with ERFA's positions given; drag in the config's atmosphere, NRLMSISE-00;
SRP in the conical shadow), then one
integrator step (four stages: C_cirs_gcrf once, the Earth rotation angle, the Sun and the Moon at
each new time) for configs/one_day_perturbed.yaml's parameters with terms switched off one at a
time, and the component's ``do_step`` (60 s of 10 s steps, its outputs packed). CPU time of the
thread, median over batches, lowest of ``--repeat`` passes (as benchmarks/bench_orbit.py).
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_orbit import cpu_time_per_step  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

CONFIG = ROOT / "configs" / "one_day_perturbed.yaml"
S = 1_000_000_000


def harness(**changes) -> Harness:
    config = yaml.safe_load(CONFIG.read_text())
    params = {**config["components"]["orbit"]["parameters"], **changes}
    h = Harness("orbit.numerical", params, epoch=str(config["run"]["epoch"]))
    h.initialize()
    return h


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(
        f"orbit.numerical CPU time ({platform.processor() or platform.machine()}, Python {platform.python_version()})"
    )
    full = harness()
    propagator = full.component.propagator
    r, v = propagator.r, propagator.v
    instant = propagator.surroundings.at(0.0)
    from components.orbit import numerical
    from components.space.gravity import GravityField

    terms = {t.name: t for t in propagator.terms}
    rows = [("point_mass", terms["point_mass"])]
    rows += [(f"harmonics {n} x {m}", numerical.Harmonics(GravityField(n, m))) for n, m in ((2, 0), (6, 0), (20, 20))]
    rows += [(name, terms[name]) for name in ("sun", "moon", "drag", "srp")]
    for label, term in rows:
        us = cpu_time_per_step(lambda k, term=term: term.acceleration(instant, r, v), args.steps, args.repeat) * 1e6
        print(f"  term {label:<34}{us:9.1f} us/evaluation")
    alone = dict(third_bodies=[], drag=None, atmosphere=None, srp=None, mass=None)
    for label, h in (
        ("all on (20 x 20, sun, moon, drag, srp)", full),
        ("no drag", harness(drag=None, atmosphere=None)),
        ("no srp", harness(srp=None)),
        ("no sun, moon", harness(third_bodies=[])),
        ("gravity 2 x 0 only", harness(gravity={"degree": 2, "order": 0}, **alone)),
        ("point mass only", harness(gravity={"degree": 0, "order": 0}, **alone)),
    ):
        p = h.component.propagator
        us = cpu_time_per_step(lambda k, p=p: p.state_at(p.t_ns + p.step_ns), args.steps, args.repeat) * 1e6
        print(f"  RK4 step (10 s), {label:<34}{us:9.1f} us/step")
    outputs = full.output_layout.start_vector()
    component = full.component

    def do_step(k):
        full.output_layout.pack(component.do_step(component.propagator.t_ns, 60 * S, {}), outputs)

    us = cpu_time_per_step(do_step, max(args.steps // 10, 20), args.repeat) * 1e6
    print(f"  do_step (60 s: 6 RK4 steps) + output packing, all on{us:12.1f} us/step")


if __name__ == "__main__":
    main()
