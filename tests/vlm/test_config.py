"""The simulated VLM's profiles: the generic ones here, a task's own from its Task, looked up with it."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from vlmrl_cli.core.errors import BadInput
from vlmrl_cli.vlm.config import (
    SIM_PROFILES,
    SimKnobs,
    SimProfile,
    profile_problem,
    resolve_sim_profile,
    sim_identity,
    sim_profiles,
)


@dataclass(frozen=True)
class _Task:
    """The two things the profile lookup asks of a task (a ``ProfileOwner``)."""

    name: str
    sim_profiles: tuple[SimProfile, ...] = ()


STUCK = SimProfile("stuck", {"flicker": 0.0, "float_anchor": 0.5})
TOY = _Task("toy", (STUCK,))


def test_the_generic_profiles_name_no_task_knob() -> None:
    # MountainCar's knobs mean nothing without its reader: no generic profile sets them
    assert list(SIM_PROFILES) == ["ideal", "default"]
    task_knobs = {"float_anchor", "mcq_bottom_halfwidth", "box_anchor_x"}
    assert not any(task_knobs & set(knobs) for knobs in SIM_PROFILES.values())


def test_a_task_adds_its_profiles_after_the_generic_ones() -> None:
    assert list(sim_profiles(TOY)) == ["ideal", "default", "stuck"]
    assert list(sim_profiles()) == list(sim_profiles(_Task("bare"))) == ["ideal", "default"]
    knobs = SimKnobs.of_profile("stuck", TOY, flicker=0.2)
    assert (knobs.profile, knobs.flicker, knobs.float_anchor) == ("stuck", 0.2, 0.5)


def test_a_profile_a_task_does_not_offer_is_one_sentence_naming_the_task() -> None:
    problem = profile_problem("stuk", TOY)
    assert problem == ("unknown simulated-VLM profile 'stuk' for task toy (did you mean 'stuck'?); "
                       "choose from ideal, default, stuck")
    assert profile_problem("stuck", _Task("other")) is not None and profile_problem("ideal", _Task("other")) is None
    with pytest.raises(BadInput, match=r"^vlm.sim.profile: unknown simulated-VLM profile 'stuck' for task other"):
        resolve_sim_profile({"profile": "stuck"}, _Task("other"))


def test_resolving_lays_the_explicit_knobs_over_the_tasks_profile() -> None:
    raw = resolve_sim_profile({"profile": "stuck", "flicker": 0.3}, TOY)
    assert raw == {"flicker": 0.3, "float_anchor": 0.5, "profile": "stuck"}
    # without the task (its name did not resolve: its own check says why) the table stays as it was
    assert resolve_sim_profile({"profile": "stuck"}) == {"profile": "stuck"}
    assert resolve_sim_profile({"flicker": 0.3}, TOY) == {"flicker": 0.3}


def test_a_task_profile_is_checked_when_it_is_made() -> None:
    with pytest.raises(ValueError, match="generic one"):
        SimProfile("default", {})
    with pytest.raises(ValueError, match="unknown knob 'float_ancor' \\(did you mean 'float_anchor'\\?\\)"):
        SimProfile("typo", {"float_ancor": 0.1})
    with pytest.raises(ValueError, match="unknown knob 'profile'"):
        SimProfile("self", {"profile": "ideal"})
    with pytest.raises(ValueError, match="twice"):
        sim_profiles(_Task("twice", (STUCK, STUCK)))


def test_a_task_profile_enters_the_identity_as_its_knobs_and_name() -> None:
    ident = sim_identity(SimKnobs.of_profile("stuck", TOY))
    assert ident["profile"] == "stuck" and ident["float_anchor"] == 0.5 and "mcq_bottom_halfwidth" not in ident
