"""The memo of held physics steps (cotwin.pmodel.memo): a stretch met again ends as stepping it would, bit for bit,
and nothing is taken from it for another stretch, another model or another number of steps."""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np
import pytest

from cotwin.cbuild import compile_library
from cotwin.mapping import native
from cotwin.pmodel import memo
from cotwin.pmodel.simulator import STATE, PlatformSimulator
from cotwin.twin.assembly.run import load

HARNESS = memo.SOURCE + r"""
void held_steps(void (*step)(const void *, void *), const void *model, void *data, int n, cotwin_memo *memo,
                int *flags) {
    cotwin_held(step, model, data, n, memo, flags);
}
"""


@pytest.fixture(scope="module")
def held():
    """n held steps of a simulator, through its memo when it has one (the C the native loop calls)."""
    try:
        lib = compile_library(HARNESS, "memo-test", keep_gil=False)
    except ValueError as why:
        pytest.skip(f"the memo's C cannot be built here: {why}")
    step = native._mj_step()
    fn = lib.held_steps
    fn.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]

    def steps(sim: PlatformSimulator, n: int) -> None:  # the sensors in the last step only, as the native loop has them
        fn(step, sim.model._address, sim.data._address, n, sim.memo.address if sim.memo is not None else None,
           sim.sensor_flags())

    return steps


@pytest.fixture(scope="module")
def twin():
    from conftest import EXAMPLES

    return load(EXAMPLES / "ur5e" / "cotwin.toml")


def simulator(twin) -> PlatformSimulator:
    sim = PlatformSimulator(twin.models.tree, twin.models.scene)
    sim.data.ctrl[:6] = [0.4, -1.2, 1.1, -1.3, -1.4, 0.2]  # a pose away from the start: the arm moves to it
    mujoco.mj_step(sim.model, sim.data, 37)
    return sim


def state(sim: PlatformSimulator) -> np.ndarray:
    vector = np.empty(mujoco.mj_stateSize(sim.model, STATE))
    mujoco.mj_getState(sim.model, sim.data, vector, STATE)
    return vector


def restore(sim: PlatformSimulator, vector: np.ndarray) -> None:
    """`vector` restored, what is read between steps computed at it (as a fork's restore does)."""
    mujoco.mj_setState(sim.model, sim.data, vector, STATE)
    mujoco.mj_forward(sim.model, sim.data)


def after(sim: PlatformSimulator) -> list[bytes]:
    """What anyone reads after the steps: the state, sensors, poses, contacts and their distances."""
    d = sim.data
    return [state(sim).tobytes(), d.sensordata.tobytes(), d.xpos.tobytes(), d.xmat.tobytes(), d.qacc.tobytes(),
            d.actuator_force.tobytes(), d.ncon.to_bytes(4, "little"), d.contact.dist[:d.ncon].tobytes(),
            d.efc_force.tobytes()]


def stepped(twin, start: np.ndarray, n: int, edit=lambda sim: None) -> list[bytes]:
    """What MuJoCo alone reads after n steps of a fresh simulator restored to `start` and then `edit`-ed."""
    reference = simulator(twin)
    restore(reference, start)
    edit(reference)
    mujoco.mj_step(reference.model, reference.data, n)
    return after(reference)


def test_a_stretch_met_again_ends_where_stepping_it_ends_bit_for_bit(twin, held):
    plain, remembering = simulator(twin), simulator(twin)
    start = state(plain)
    held(plain, 120)  # no memo: MuJoCo's steps
    expected = after(plain)
    memo = remembering.remember_held_steps()
    held(remembering, 120)  # a stretch not seen: stepped, and kept
    assert (memo.hits, memo.misses, memo.stretches) == (0, 1, 1)
    assert after(remembering) == expected
    for _ in range(2):  # met again: from the memo, the same to the bit
        restore(remembering, start)
        held(remembering, 120)
        assert after(remembering) == expected
    assert memo.hits == 2
    held(remembering, 120)  # and on from there, as MuJoCo goes on
    held(plain, 120)
    assert after(remembering) == after(plain)


def test_another_state_or_number_of_steps_is_stepped_not_taken_from_the_memo(twin, held):
    sim = simulator(twin)
    memo = sim.remember_held_steps()
    start = state(sim)
    held(sim, 50)
    restore(sim, start)
    held(sim, 60)  # the same state, more steps
    restore(sim, start)
    sim.data.ctrl[0] += 1e-12  # the same positions, another control
    held(sim, 50)
    assert memo.hits == 0 and memo.stretches == 3
    assert after(sim) == stepped(twin, start, 50, lambda reference: reference.data.ctrl.__setitem__(0, sim.data.ctrl[0]))


def test_a_body_given_another_mass_forgets_the_steps_of_the_model_before(twin, held):
    """A fork restored with a payload (PlatformSimulator.set_bodies) steps its model as it now is."""
    sim = simulator(twin)
    memo = sim.remember_held_steps()
    start = state(sim)
    held(sim, 80)
    body = sim.model.body(sim.model.nbody - 1).name
    sim.set_bodies({body: [float(sim.model.body_mass[-1]), *map(float, sim.model.body_inertia[-1])]})
    assert memo.stretches == 1  # the same mass: the memo kept
    sim.set_bodies({body: [3.5, 0.01, 0.01, 0.01]})
    assert memo.stretches == 0
    restore(sim, start)
    held(sim, 80)
    assert memo.hits == 0
    assert after(sim) == stepped(twin, start, 80, lambda reference: reference.set_bodies({body: [3.5, 0.01, 0.01, 0.01]}))


def test_a_full_memo_keeps_its_stretches_and_steps_the_new_ones(twin, held):
    sim = simulator(twin)
    sim.memo = memo.StepMemo(sim.model, budget=1)  # room for one stretch
    kept = sim.memo
    start = state(sim)
    held(sim, 30)
    first = after(sim)
    held(sim, 30)  # another stretch: stepped, not kept
    assert (kept.stretches, kept.misses) == (1, 2)
    restore(sim, start)
    held(sim, 30)
    assert kept.hits == 1 and after(sim) == first


def test_a_stretch_in_contact_met_again_ends_as_stepping_it_ends(twin, held):
    """The arm driven into the table and the plate: constraint forces and contacts after a hit are MuJoCo's."""
    rng = np.random.default_rng(1)
    tried = 0
    for _ in range(60):
        ctrl = rng.uniform(-2.5, 2.5, 6).tolist()
        sims = [PlatformSimulator(twin.models.tree, twin.models.scene) for _ in range(2)]
        for sim in sims:
            sim.data.ctrl[:6] = ctrl
            mujoco.mj_step(sim.model, sim.data, 400)
        plain, remembering = sims
        if plain.data.ncon == 0:
            continue
        start = state(plain)
        held(plain, 50)
        memo = remembering.remember_held_steps()
        held(remembering, 50)
        restore(remembering, start)
        held(remembering, 50)
        assert memo.hits == 1 and after(remembering) == after(plain)
        tried += 1
        if tried == 3:
            break
    assert tried == 3, "random set-points drive the arm into the scene"


@pytest.mark.parametrize("change", ["gravity", "damping", "gain"])
def test_a_change_of_the_models_numbers_forgets_the_steps_of_the_model_before(twin, held, change):
    """The native loop checks the model's digest before each stretch (StepMemo.check): a calibrated gain, damping
    or gravity changed on the fork's model is stepped as it now is."""
    sim = simulator(twin)
    memo = sim.remember_held_steps()
    start = state(sim)
    held(sim, 60)
    memo.check(sim.model)
    assert memo.stretches == 1  # nothing changed: kept
    edit = {"gravity": lambda m: m.opt.gravity.__setitem__(2, -9.7),
            "damping": lambda m: m.dof_damping.__setitem__(0, m.dof_damping[0] + 1.0),
            "gain": lambda m: m.actuator_gainprm.__setitem__((0, 0), m.actuator_gainprm[0, 0] * 1.1)}[change]
    edit(sim.model)
    memo.check(sim.model)
    assert memo.stretches == 0
    restore(sim, start)
    held(sim, 60)
    assert memo.hits == 0 and after(sim) == stepped(twin, start, 60, lambda reference: edit(reference.model))


def test_no_memo_where_mujoco_keeps_state_outside_the_integration_state(twin):
    sleep = getattr(mujoco.mjtEnableBit, "mjENBL_SLEEP", None)
    if sleep is None:
        pytest.skip(f"MuJoCo {mujoco.__version__} has no sleeping bodies")
    sim = simulator(twin)
    sim.model.opt.enableflags |= int(sleep)
    assert not memo.remembers(sim.model) and sim.remember_held_steps() is None


def test_sensors_the_user_turned_off_stay_off_through_the_memo(twin, held):
    """A held stretch, stepped or taken from the memo, leaves the sensors the user turned off as they were."""
    sim = simulator(twin)
    memo = sim.remember_held_steps()
    assert sim.sensor_flags() is not None  # looked up while the sensors are on
    sim.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    memo.check(sim.model)
    start = state(sim)
    for _ in range(2):  # stepped, then taken from the memo
        restore(sim, start)
        held(sim, 40)
        assert sim.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_SENSOR
    assert memo.hits == 1
    for n in (1, 5):  # fewer steps than a memo's stretch: stepped as they are
        held(sim, n)
        assert sim.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_SENSOR


def test_a_memo_keeps_and_takes_nothing_once_its_models_bodies_may_sleep(twin, held):
    """Sleeping bodies are state outside the integration state: a memo made before the model's bodies were let
    sleep forgets its stretches at the next check and keeps no new one while they may; again once they may not."""
    sleep = getattr(mujoco.mjtEnableBit, "mjENBL_SLEEP", None)
    if sleep is None:
        pytest.skip(f"MuJoCo {mujoco.__version__} has no sleeping bodies")
    sim = simulator(twin)
    memo = sim.remember_held_steps()
    start = state(sim)
    held(sim, 60)
    assert memo.stretches == 1
    sim.model.opt.enableflags |= int(sleep)
    memo.check(sim.model)
    for _ in range(2):
        restore(sim, start)
        held(sim, 60)
    assert (memo.hits, memo.stretches) == (0, 0)
    sim.model.opt.enableflags &= ~int(sleep)
    memo.check(sim.model)
    held(sim, 60)
    assert memo.stretches == 1
