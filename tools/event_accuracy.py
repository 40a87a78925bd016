"""Accuracy of tswm at its events against the independent quadrature reference.

Prints, for both methods over rtol (atol = rtol 1e-3): the Painleve point of the paper
gear (m2 = 5000 kg, +60 kN from 0.04 s), the one-sided reaction maxima of m2 = 100 kg
under +30 kN from 2 ms, v1 at a load step and at t_end (-5 kN at 0.05 s, while the gear
still runs up) in units of rtol, and the held equilibrium tail at T = 100 s.

Run: ``python tools/event_accuracy.py``
"""
from tswm_runtime.reference import quadrature as q
from tswm_runtime.simulation.simulate import METHOD_RTOL_MIN, simulate

METHODS = ("dopri5", "rosenbrock23")


def run(params, method, rtol, **settings):
    return simulate("paper-runup", params, method=method, rtol=rtol, atol=rtol * 1e-3, **settings)


def painleve():
    ref = q.solve(q.paper_wedge(5000.0), [(0.0, 0.0), (0.04, 60000.0)], 0.0, 1.0)
    t_star = float(ref.t_stop)
    print(f"Painleve point: reference {ref.status} at t* = {t_star:.13f} s, v* = {float(ref.events[-1].v):.12f} m/s")
    for method in METHODS:
        for rtol in (1e-3, 1e-6, 1e-9):
            r = run({"m2": 5000.0, "F2_after": 60000.0, "t_step": 0.04}, method, rtol)
            print(f"  {method:12s} rtol {rtol:.0e}: {r.status}, t = {r.t_stop:.11f} s, |dt|/t* = "
                  f"{abs(r.t_stop - t_star) / t_star:.1e}, S1_max = {r.S1_max}, S2_max = {r.S2_max}")


def one_sided_maxima():
    ref = q.solve(q.paper_wedge(100.0), [(0.0, 0.0), (0.002, 30000.0)], 0.0, 1.0).S_extrema()
    print("One-sided maxima, m2 = 100 kg, +30 kN from 2 ms (reference S1 = "
          f"{float(ref['S1'][0]):.6f} N at {float(ref['S1'][1]):.9f} s):")
    for method in METHODS:
        r = run({"m2": 100.0, "F2_after": 30000.0, "t_step": 0.002}, method, 1e-8)
        print(f"  {method:12s} rtol 1e-08: S1_max = {r.S1_max:.6f} N at {r.t_S1_max:.9f} s, relative errors "
              f"S1 {abs(r.S1_max / float(ref['S1'][0]) - 1):.1e}, S2 {abs(r.S2_max / float(ref['S2'][0]) - 1):.1e}")


def load_step():
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0), (0.05, -5000.0)], 0.0, 1.0)
    v_step, v_end = float(ref.v_at(0.05)), float(ref.v_at(1.0))
    print("v1 at the load step (0.05 s, -5 kN) and at t_end, relative error / rtol:")
    for method in METHODS:
        for rtol in (1e-3, 1e-6, 1e-8, max(1e-10, METHOD_RTOL_MIN[method][0])):
            r = run({"F2_after": -5000.0, "t_step": 0.05}, method, rtol)
            print(f"  {method:12s} rtol {rtol:.0e}: at the step {abs(r.events[0].v1 / v_step - 1) / rtol:6.2f}, "
                  f"at t_end {abs(r.v1[-1] / v_end - 1) / rtol:6.2f}")


def held_tail():
    ref = q.solve(q.paper_wedge(200.0), [(0.0, 0.0), (0.3, -15000.0)], 0.0, 100.0)
    v, x = float(ref.v_at(100.0)), float(ref.x_at(100.0))
    print("Equilibrium tail, T = 100 s (default rtol 1e-6):")
    for method in METHODS:
        steps = {T: run({"F2_after": -15000.0}, method, 1e-6, t_end=T) for T in (1.0, 100.0)}
        r = steps[100.0]
        print(f"  {method:12s} steps T=1: {steps[1.0].n_steps}, T=100: {r.n_steps}; relative error at 100 s: "
              f"v1 {abs(r.v1[-1] / v - 1):.1e}, x1 {abs(r.x1[-1] / x - 1):.1e}")


if __name__ == "__main__":
    painleve()
    one_sided_maxima()
    load_step()
    held_tail()
