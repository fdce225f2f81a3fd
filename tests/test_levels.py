"""The model-level table (rss6core.levels) tells the truth about the levels: each yes/no property is
checked against what the level does, on a short smoke run (the contact level's runs are left to
tests/test_contact.py: its compiled kernel takes minutes to build)."""
import dataclasses

import numpy as np
import pytest

from rss6core import (FINISHED, MODEL_LEVELS, MODELS, default_integrator, default_time_step, degrees_of_freedom,
                      model_level, models_with, prepare_level, simulate_batch)
from rss6core.clearance import draw_clearances
from rss6core.scene import Simulation

CHEAP = [m for m in MODELS if not MODEL_LEVELS[m].contact_joints]


@pytest.fixture(scope="module")
def short(smoke):
    return dataclasses.replace(smoke, trajectory=dataclasses.replace(smoke.trajectory, duration=0.02))


def _scaled(scene, factor):
    c = scene.clearance
    return dataclasses.replace(scene, clearance=dataclasses.replace(
        c, **{f.name: factor * getattr(c, f.name) for f in dataclasses.fields(c)}))


def test_the_table_lists_the_ladder_cheapest_first_and_names_simulation_fields():
    assert MODELS == ("rigid", "quasi-static", "elastic", "paper", "contact")
    assert [MODEL_LEVELS[m].rung for m in MODELS] == ["L0", "L1", "L2", "L3", "L4"]
    fields = {f.name: f.type for f in dataclasses.fields(Simulation)}
    for level in MODEL_LEVELS.values():
        assert fields[level.time_step_field] == "float" and fields[level.integrator_field] == "str"
    assert models_with("draws_clearances") == ("quasi-static", "paper", "contact")
    with pytest.raises(ValueError, match="unknown level property 'fast'"):
        models_with("fast")
    with pytest.raises(ValueError, match="unknown model 'fem'; choose one of rigid, quasi-static"):
        model_level("fem")


def test_only_the_contact_level_has_its_own_step_and_integrator(smoke):
    sim = smoke.simulation
    assert (sim.contact_time_step, sim.contact_integrator) != (sim.time_step, sim.integrator)
    own = {m: (default_time_step(smoke, m), default_integrator(smoke, m)) for m in MODELS}
    assert own == {m: (sim.contact_time_step, sim.contact_integrator) if m == "contact"
                   else (sim.time_step, sim.integrator) for m in MODELS}


@pytest.mark.parametrize("model", CHEAP)
def test_draws_clearances_and_linear_in_clearances_say_what_the_level_does(short, model):
    """Two realisations differ exactly where the level draws clearances; doubling every clearance
    doubles the error (to rounding) exactly where such a level is linear in them."""
    kind = model_level(model)
    one, two = simulate_batch(short, model, realizations=[0, 1])
    assert (not np.array_equal(one.displacement, two.displacement)) == kind.draws_clearances
    if kind.draws_clearances:
        doubled = simulate_batch(_scaled(short, 2.0), model, realizations=[0])[0]
        linear = np.allclose(doubled.displacement, 2 * one.displacement, rtol=1e-9, atol=0.0)
        assert linear == kind.linear_in_clearances


@pytest.mark.parametrize("model", CHEAP)
def test_function_of_one_draw_and_elastic_links_say_what_the_level_does(short, model):
    """A level takes given draws exactly where its error is a function of one draw; it solves for
    more than the 6 pose errors exactly where its links are elastic."""
    kind = model_level(model)
    level = prepare_level(short, model)
    draws = [draw_clearances(short, 0, 0)]
    if kind.function_of_one_draw:
        assert level.simulate_draws(draws)[0].status == FINISHED
    else:
        with pytest.raises(ValueError, match="takes no given draws"):
            level.simulate_draws(draws)
    assert (degrees_of_freedom(short, model) > 6) == kind.elastic_links
    assert (level.integrator is not None) == kind.elastic_links


def test_redraws_every_step_says_what_the_paper_level_does(short):
    """The paper level's eccentricities change from step to step: its error is white noise on the
    elastic one, whose increments dwarf the smooth levels' (the quasi-static error is a smooth map)."""
    for model in ("quasi-static", "paper"):
        r = simulate_batch(short, model, realizations=[0])[0]
        base = simulate_batch(short, "elastic")[0].displacement if MODEL_LEVELS[model].elastic_links else 0.0
        kinematic = r.displacement - base
        rough = np.abs(np.diff(kinematic, 2, axis=0)).max() / np.abs(kinematic).max()
        assert (rough > 0.1) == MODEL_LEVELS[model].redraws_every_step, (model, rough)
