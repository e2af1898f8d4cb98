"""Stability-aware ranking: isf.plan(rank="quality") and rank="fit", their JSON and CLI flags."""

import json
import subprocess
import sys

import jsonschema
import numpy as np
import pytest
from _builders import sphere_contacts

import isf
from isf.planning.plan_json import SCHEMA_PATH
from isf.quality import MARGIN_TARGET, QualityConfig, grasp_quality, object_properties


@pytest.fixture(scope="module")
def plans(paper_gripper, cylinder):
    """The same run ranked both ways (the loop does not depend on the ranking)."""
    return (isf.plan(paper_gripper, cylinder, samples=12, seed=0, diversity=None),
            isf.plan(paper_gripper, cylinder, samples=12, seed=0, diversity=None, rank="fit"))


def test_quality_ranking_puts_resisting_grasps_first(plans, paper_gripper, cylinder):
    by_quality, by_fit = plans
    assert sorted(g.sample_index for g in by_quality.grasps) == list(range(12))
    assert by_quality.rank == "quality" and by_fit.rank == "fit"
    assert all((g.quality is not None) == g.valid for g in by_quality.grasps)
    assert all(g.quality is None for g in by_fit.grasps)
    assert by_fit.stats.quality_time == 0.0 < by_quality.stats.quality_time
    # the fit ranking is the paper's: by mean distance within each validity class
    keys = [g.sort_key() for g in by_fit.grasps]
    assert keys == sorted(keys)
    # independently recomputed: no valid grasp whose equal squeeze friction can absorb holds
    # better than the top one, and among those that hold as well, none has its contacts
    # nearer the centre of mass
    properties = object_properties(cylinder)
    valid = [g for g in by_fit.grasps if g.valid]

    def balanced(grasp) -> bool:
        contacts = isf.quality.grasp_contacts(paper_gripper, cylinder, grasp.T_object_gripper,
                                              grasp.q, by_quality.quality.contact_model)
        normals = [contacts.normals[contacts.surface == s].mean(axis=0)
                   for s in np.unique(contacts.surface)]
        push = sum(n / np.linalg.norm(n) for n in normals)
        return bool(normals) and np.linalg.norm(push) / len(normals) <= by_quality.quality.friction

    valid = [g for g in valid if balanced(g)] or valid
    recomputed = [grasp_quality(paper_gripper, cylinder, g.T_object_gripper, g.q,
                                by_quality.quality, properties) for g in valid]
    assert recomputed
    held = [min(q.min_margin, MARGIN_TARGET) for q in recomputed]
    best = by_quality.best.quality
    assert min(best.min_margin, MARGIN_TARGET) == pytest.approx(max(held))
    ties = [q for q, h in zip(recomputed, held) if h == pytest.approx(max(held))]
    assert best.com_offset == pytest.approx(min(q.com_offset for q in ties))
    centroid = isf.quality.grasp_contacts(
        paper_gripper, cylinder, by_quality.best.T_object_gripper, by_quality.best.q,
        by_quality.quality.contact_model).points.mean(axis=0)
    assert best.com_offset == pytest.approx(np.linalg.norm(centroid - properties.center_of_mass))


def _full_key(grasp) -> tuple:
    """The ranking key with every metric computed, epsilon included (the reference order)."""
    q = grasp.quality
    quality = ((1, True, True, 0.0, 0.0, 0.0) if q is None else
               (0, bool(grasp.closing_obstructed_by), not q.squeeze_balanced,
                -min(q.min_margin, MARGIN_TARGET), q.com_offset, -q.epsilon))
    return (not grasp.collision_free, not grasp.in_contact, not grasp.one_piece,
            grasp.settled is False, *quality, grasp.fit.mean_distance, grasp.sample_index)


@pytest.mark.parametrize("gripper_name, shape", [("paper-parallel", "shape:cylinder"),
                                                 ("flat-parallel", "shape:box"),
                                                 ("three-finger", "shape:cylinder")])
def test_ranking_order_is_that_of_every_metric_computed(gripper_name, shape):
    """The planner reads epsilon only to break ties and the margin's value only below the
    target; its order is the one every metric, computed in full, gives."""
    result = isf.plan(isf.load_gripper(gripper_name), isf.open_object(shape), samples=16,
                      seed=3, diversity=None)
    assert [g.sample_index for g in result.grasps] == \
        [g.sample_index for g in sorted(result.grasps, key=_full_key)]


def test_friction_changes_the_quality(paper_gripper, cylinder):
    slippery = isf.plan(paper_gripper, cylinder, samples=6, seed=0,
                        quality=QualityConfig(friction=0.1))
    grippy = isf.plan(paper_gripper, cylinder, samples=6, seed=0,
                      quality=QualityConfig(friction=0.8))
    for a, b in zip(sorted(slippery.grasps, key=lambda g: g.sample_index),
                    sorted(grippy.grasps, key=lambda g: g.sample_index)):
        if a.valid:
            assert a.quality.friction == 0.1 and b.quality.friction == 0.8
            assert a.quality.epsilon < b.quality.epsilon


def test_plan_rejects_unknown_ranking(paper_gripper, cylinder):
    with pytest.raises(isf.InvalidInputError, match="rank must be"):
        isf.plan(paper_gripper, cylinder, samples=2, rank="best")
    with pytest.raises(isf.InvalidInputError, match="QualityConfig"):
        isf.plan(paper_gripper, cylinder, samples=2, quality={"friction": 0.5})


def run(*args):
    return subprocess.run([sys.executable, "-m", "isf", *args], capture_output=True, text=True,
                          timeout=300)


@pytest.mark.parametrize("flags, rank", [(("--friction", "0.3"), "quality"),
                                         (("--rank", "fit"), "fit")])
def test_cli_rank_and_friction_write_valid_json(tmp_path, flags, rank):
    out = tmp_path / "grasps.json"
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "4", "--out", str(out),
               "--quiet", *flags)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    jsonschema.validate(data, json.loads(SCHEMA_PATH.read_text()))
    assert data["ranking"]["rank"] == rank
    records = [g["quality"] for g in data["grasps"]]
    if rank == "fit":
        assert data["ranking"]["quality"] is None and records == [None] * 4
    else:
        assert data["ranking"]["quality"]["friction"] == 0.3
        valid = [r for r, g in zip(records, data["grasps"]) if g["valid"]]
        assert valid and all(r["friction"] == 0.3 and set(r["gravity_margin"]) ==
                             {"+x", "-x", "+y", "-y", "+z", "-z"} for r in valid)
        assert np.isfinite([r["epsilon"] for r in valid]).all()


def test_cli_mass_scales_the_gravity_margins(tmp_path):
    """A margin is the largest load the contacts resist over the object's weight, so the same
    grasps planned for a third of the mass have three times the margins."""
    plans = {}
    for mass in ("0.3", "0.1"):
        out = tmp_path / f"m{mass}.json"
        proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "4", "--out",
                   str(out), "--quiet", "--mass", mass)
        assert proc.returncode == 0, proc.stderr
        data = json.loads(out.read_text())
        assert data["ranking"]["quality"]["mass"] == float(mass)
        plans[mass] = {g["sample_index"]: g for g in data["grasps"] if g["valid"]}
    assert plans["0.3"] and plans["0.3"].keys() == plans["0.1"].keys()
    for index, heavy in plans["0.3"].items():
        light = plans["0.1"][index]
        np.testing.assert_allclose(light["T_object_gripper"], heavy["T_object_gripper"])
        for direction, margin in heavy["quality"]["gravity_margin"].items():
            assert light["quality"]["gravity_margin"][direction] == pytest.approx(3 * margin,
                                                                                 rel=1e-6)


def test_cli_rejects_a_mass_that_is_not_positive():
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2", "--mass", "0")
    assert proc.returncode == 2
    assert "mass" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_cli_rejects_negative_friction():
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2", "--friction", "-1")
    assert proc.returncode == 2
    assert "friction" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_margins_ordered_by_bounds_as_by_their_values():
    """The ranking compares the held margins of grasps that do not hold by bounds from
    feasibility tests; the order is the one the computed margins give, also for near-equal
    margins (the same contacts moved by 1e-12 m: the values decide), and the bounds settle
    the others without computing a margin."""
    from isf.quality import Contacts, quality_rank_key

    rng = np.random.default_rng(4)
    qualities, pushes = [], []
    for k in range(40):  # three or four point contacts on a 3 cm sphere, pushing inwards
        points, normals, properties = sphere_contacts(rng, 3, 5)
        for shift in (0.0, 1e-12) if k % 4 == 0 else (0.0,):
            contacts = Contacts.from_points(points + shift, normals)
            qualities.append(isf.quality.contacts_quality(contacts, properties,
                                                          QualityConfig(mass=1.0)))
            unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
            pushes.append(np.linalg.norm(unit.sum(axis=0)) / len(unit) > 0.5)
    lazy = sorted(range(len(qualities)), key=lambda k: quality_rank_key(qualities[k], 0.0))
    computed = sum("held_margin" in q.__dict__ and 0 < q.held_margin < MARGIN_TARGET
                   for q in qualities)
    below = sum(0 < q.min_margin < MARGIN_TARGET for q in qualities)  # now every value
    full = sorted(range(len(qualities)), key=lambda k: (pushes[k],
                                                        -min(qualities[k].min_margin,
                                                             MARGIN_TARGET),
                                                        qualities[k].com_offset,
                                                        -qualities[k].epsilon))
    assert lazy == full
    assert below >= 10 and computed < below
