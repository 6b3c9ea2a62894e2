"""Every kernel argument goes to the parameter of its name.

The simulator calls its kernels with the containers of ``dbtool.sim.state`` unpacked in field
order (``p2g(*state, *body.stress, ..., *consts)``); reordering two fields of a container would
still compile and silently change the physics. These tests name every argument of every kernel
call of a substep, its adjoint and a control step by where it came from (which container field
holds the array, which scene, material or region value the scalar is) and check it against the
kernel's parameter name, for the CPU and GPU variants, with and without a task object's field.
"""

from collections import defaultdict
from dataclasses import fields

import numpy as np
import pytest
from taichi.lang._ndarray import Ndarray

from dbtool.sim import backward
from dbtool.sim import kernels as K
from dbtool.sim.bodies import lattice
from dbtool.sim.graphs import _params
from dbtool.sim.simulator import Particles, Scene, Simulator
from dbtool.sim.state import Constants

# kernel parameters whose array is named otherwise in its container
ALIASES = {"out": "cbox", "ngrid": "adj.ngrid"}


def _block(origin, side):
    x0 = lattice((side,) * 3, 0.0025) + np.asarray(origin)
    n = len(x0)
    return Particles(x0=x0, presence=np.ones(n), stiffness=np.full(n, 3e4),
                     actuators=np.zeros((n, 4)), direction=np.tile([0.0, 1.0, 0.0], (n, 1)),
                     glued=np.zeros(n), v0=np.zeros((n, 3)))


def _simulator(multi: bool) -> Simulator:
    """A robot block and (``multi``) a cube in its own field; a grid with three different
    sizes, distinct friction coefficients and a damping rate, so no two values coincide."""
    robot = _block((0.07, 0.05, 0.04), 0.01)
    if multi:
        cube = _block((0.03, 0.02, 0.09), 0.01)
        parts = Particles(*(np.concatenate([getattr(robot, f), getattr(cube, f)])
                            for f in ("x0", "presence", "stiffness", "actuators", "direction",
                                      "glued", "v0")),
                          field=np.r_[np.zeros(robot.n), np.ones(cube.n)])
    else:
        parts = robot
    scene = Scene(size=(0.12, 0.1, 0.135), ground_y=0.015, friction=0.4, damping=2.0,
                  object_friction=0.7 if multi else None)
    sim = Simulator(scene, parts, n_steps=2)
    sim.forward(np.zeros((2, 4)))
    return sim


def _array_names(sim: Simulator) -> dict[int, set[str]]:
    """id(array) -> the names it has in the simulator's containers."""
    names: dict[int, set[str]] = defaultdict(set)
    sp = sim.stepper
    for prefix, obj in (("", sim.state), ("", sim.body), ("grid.", sim.grid),
                        ("adj.", sim.adjoint)):
        for f in fields(obj):
            value = getattr(obj, f.name)
            if isinstance(value, Ndarray):
                names[id(value)].add(prefix + f.name)
    names[id(sp.boxes)].add("boxes")
    names[id(sp.cbox)].add("cbox")
    return names


def _array_ok(param: str, names: set[str]) -> bool:
    """State and body fields go by their own names, grid fields by theirs with or without
    ``grid_``, adjoints by the primal name with one ``g`` added (``xg``, ``ggrid``,
    ``ogscratch``)."""
    if ALIASES.get(param) in names or param in names:  # state and body names carry no prefix
        return True
    for name in names:
        kind, _, field = name.rpartition(".")
        if kind == "grid" and param in (field, f"grid_{field}"):
            return True
        if kind == "adj" and any(param[:i] + param[i + 1:] == field
                                 for i, ch in enumerate(param) if ch == "g"):
            return True
    return False


def _scalars(sim: Simulator, region, slots: dict[str, int]) -> dict[str, float]:
    """The value each scalar parameter must receive."""
    sp, sc, mat = sim.stepper, sim.scene, sim.mat
    nx, ny, nz = sp.dims
    (lx, ly, lz), (hx, hy, hz) = region.lo, region.hi
    values = {f.name: getattr(sp.consts, f.name) for f in fields(Constants)}
    values.update(
        n=sp.n, chunks=sp.chunks, nx=nx, ny=ny, nz=nz, lx=lx, ly=ly, lz=lz, hx=hx, hy=hy,
        hz=hz, dx=sc.dx, dt=mat.dt, gravity=sc.gravity, ground_y=sc.ground_y,
        mu_f=sc.friction, damp=sc.damp(mat.dt), mu_c=sc.object_friction or 0.0,
        multi=sim.grid.multi, **slots)
    if sp.object_span is not None:
        values.update(a=sp.object_span[0], b=sp.object_span[1])
    return values


def _mismatches(sim: Simulator, calls, region, slots: dict[str, int]) -> list[str]:
    arrays = _array_names(sim)
    scalars = _scalars(sim, region, slots)
    bad = []
    for kernel, args in calls:
        params = _params(kernel)
        assert len(params) == len(args), kernel
        for param, value in zip(params, args, strict=True):
            where = f"{kernel.__name__}({param})"
            if isinstance(value, Ndarray):
                if not _array_ok(param, arrays.get(id(value), set())):
                    bad.append(f"{where} got {sorted(arrays.get(id(value), {'?'}))}")
            elif param not in scalars:
                bad.append(f"{where}: no known value")
            elif value != scalars[param]:
                bad.append(f"{where} got {value!r}, expected {scalars[param]!r}")
    return bad


def _calls(sim: Simulator, atomic: bool, replay: bool):
    sp = sim.stepper
    region = sim.regions[0]
    s = 3
    saved, sp.atomic = sp.atomic, atomic
    try:
        forward = sp.substep_calls(s, region, replay=replay)
        adjoint = backward._substep_adjoint(sp, sim.adjoint, s, region)
    finally:
        sp.atomic = saved
    slot, so, gs = sp.slots(s, replay)
    return forward, adjoint, region, {"s": slot, "so": so, "gs": gs}, s


@pytest.mark.parametrize("multi", [False, True])
@pytest.mark.parametrize("atomic", [False, True])
def test_every_kernel_argument_reaches_the_parameter_of_its_name(multi, atomic):
    sim = _simulator(multi)
    assert sim.multi == multi
    for replay in (False, True):
        forward, adjoint, region, slots, s = _calls(sim, atomic, replay)
        assert _mismatches(sim, forward, region, slots) == []
        # the adjoint of substep s reads and writes substep s's own slots
        assert _mismatches(sim, adjoint, region, {"s": s}) == []
    b = sim.body  # a control step's muscle signal (Stepper.segment)
    assert _mismatches(sim, [(K.actuation, (b.actuators, b.act, b.actp, 1, sim.stepper.n))],
                       sim.regions[0], {"t": 1}) == []


def test_a_swapped_argument_is_caught():
    """Two float constants exchanged, or two arrays of one container, fail the check."""
    sim = _simulator(True)
    forward, adjoint, region, slots, _ = _calls(sim, False, False)
    kernel, args = next(c for c in forward if c[0].__name__ == "p2g")
    params = _params(kernel)
    i, j = params.index("nu"), params.index("act_strength")
    swapped = list(args)
    swapped[i], swapped[j] = swapped[j], swapped[i]
    assert len(_mismatches(sim, [(kernel, tuple(swapped))], region, slots)) == 2
    i, j = params.index("v"), params.index("x")
    swapped = list(args)
    swapped[i], swapped[j] = swapped[j], swapped[i]
    assert len(_mismatches(sim, [(kernel, tuple(swapped))], region, slots)) == 2
    kernel, args = next(c for c in adjoint if c[0].__name__ == "p2g_grad")
    params = _params(kernel)
    i, j = params.index("x"), params.index("xg")  # a primal array for its adjoint
    swapped = list(args)
    swapped[i], swapped[j] = swapped[j], swapped[i]
    assert len(_mismatches(sim, [(kernel, tuple(swapped))], region, {"s": 3})) == 2


def test_an_arm64_cpu_runs_the_cpu_kernels(monkeypatch):
    """Taichi's arm64 backend is a CPU: per-thread grid copies, not the GPU's atomics."""
    import taichi as ti

    from dbtool.sim import runtime

    runtime.init()

    class Config:
        arch = ti.arm64

    monkeypatch.setattr(ti.lang.impl, "current_cfg", lambda: Config)
    assert runtime.arch() == "cpu"
    Config.arch = object()  # any backend that is not one of Taichi's CPUs
    assert runtime.arch() == "gpu"
