"""The factors' proof keeps what it finished: checkpoints, resumption, the cache of finished proofs (proof.py)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import polyrob.bounds.certified.factors.proof as proof
from polyrob import load_robot
from polyrob.bounds.certified.factors import FactorProblem, prove_factor_ranges
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.errors import CertificationError
from polyrob.plant.models.inner_factors import factor_parameters

CHEAP = dict(
    pilot=32, ascent_rounds=0, box_ascent_rounds=0
)  # the steering's pilot small: these tests are about the state, not tightness


@functools.cache
def finger():
    """finger_edu's factors on a fiftieth of its task: 31 boxes in two batches, about 3 s."""
    robot = default_task_robot(load_robot("finger_edu"))
    loops = [(name, loop) for name, _, loop in factor_parameters(robot)]
    box = default_task_domain(robot).scaled(0.02)
    return loops, box, prove_factor_ranges(loops, box, **CHEAP)


def test_a_proof_given_up_goes_on_from_its_checkpoint_to_the_uninterrupted_result(tmp_path):
    loops, box, whole = finger()
    with pytest.raises(CertificationError, match="its state is kept in .*factor-proof-.*npz: the same call goes on"):
        prove_factor_ranges(loops, box, max_boxes=1, checkpoint_dir=tmp_path, **CHEAP)
    (kept,) = tmp_path.glob("factor-proof-*.npz")
    resumed = prove_factor_ranges(loops, box, checkpoint_dir=tmp_path, **CHEAP)
    assert resumed.resumed_boxes == 1 and resumed.boxes == whole.boxes == 31  # the root box was the first batch
    assert np.array_equal(resumed.lower, whole.lower) and np.array_equal(resumed.upper, whole.upper)
    assert resumed.checkpoint == str(kept)
    # finished: the next call takes it from the file without a box more, and says the work is all done
    seen = []
    again = prove_factor_ranges(loops, box, checkpoint_dir=tmp_path, progress=lambda *a: seen.append(a), **CHEAP)
    assert again.boxes == again.resumed_boxes == 31 and np.array_equal(again.upper, whole.upper)
    assert seen == [(1.0, 31, 0.0)]


def test_an_interrupted_batch_leaves_the_state_of_the_batch_before(tmp_path, monkeypatch):
    loops, box, whole = finger()
    calls = []
    enclose = proof.enclose_batch

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # Ctrl-C while the second batch is enclosed
            raise KeyboardInterrupt
        return enclose(*args, **kwargs)

    monkeypatch.setattr(proof, "enclose_batch", interrupted)
    with pytest.raises(KeyboardInterrupt):
        prove_factor_ranges(loops, box, checkpoint_dir=tmp_path, **CHEAP)
    monkeypatch.setattr(proof, "enclose_batch", enclose)
    resumed = prove_factor_ranges(loops, box, checkpoint_dir=tmp_path, **CHEAP)
    assert resumed.resumed_boxes == 1 and resumed.boxes == whole.boxes
    assert np.array_equal(resumed.lower, whole.lower) and np.array_equal(resumed.upper, whole.upper)


def test_a_damaged_file_or_another_proofs_state_is_not_gone_on_from(tmp_path):
    loops, box, whole = finger()
    problem = FactorProblem.from_loops(loops)
    settings = dict(rel_tol=proof.REL_TOL, pilot=32, seed=0, taylor=True, ascent=0, batch=proof.BATCH, box_ascent=0)
    path = tmp_path / f"factor-proof-{proof.proof_fingerprint(problem, box, **settings)}.npz"
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(CertificationError, match=r"\(\d+\.\d % of the work done, 1 box in all"):  # from the root
        prove_factor_ranges(loops, box, max_boxes=1, checkpoint_dir=tmp_path, **CHEAP)
    with np.load(path) as data:  # rewritten whole: this proof's state after its first box
        assert int(data["boxes"]) == 1 and len(data["share"]) > 0
        arrays = dict(data)
    # a finished state whose fingerprint is another proof's (a file renamed by hand) is not read either
    arrays.update(fingerprint=np.array("0" * 24), out_lo=whole.lower, out_hi=whole.upper, boxes=np.array(31))
    arrays.update({k: arrays[k][:0] for k in ("q_lo", "q_hi", "qd_lo", "qd_hi", "open", "share")})
    np.savez(path, **arrays)
    with pytest.raises(CertificationError, match="1 box in all"):  # started afresh, not returned as finished
        prove_factor_ranges(loops, box, max_boxes=1, checkpoint_dir=tmp_path, **CHEAP)
    arrays["fingerprint"] = np.array(path.stem.removeprefix("factor-proof-"))
    np.savez(path, **arrays)  # the same finished state under its own fingerprint is taken as it is
    taken = prove_factor_ranges(loops, box, max_boxes=1, checkpoint_dir=tmp_path, **CHEAP)
    assert taken.resumed_boxes == 31 and np.array_equal(taken.lower, whole.lower)


def test_the_fingerprint_follows_the_task_the_tolerance_and_the_robot():
    loops, box, _ = finger()
    problem = FactorProblem.from_loops(loops)
    base = proof.proof_fingerprint(problem, box, rel_tol=0.04)
    assert base == proof.proof_fingerprint(problem, box, rel_tol=0.04)
    assert base != proof.proof_fingerprint(problem, box.scaled(0.5), rel_tol=0.04)
    assert base != proof.proof_fingerprint(problem, box, rel_tol=0.05)
    heavier = FactorProblem(problem.chain, problem.names, problem.params * 1.001, problem.params_rad)
    assert base != proof.proof_fingerprint(heavier, box, rel_tol=0.04)


def test_at_the_work_limit_what_is_proved_by_then_holds_every_point_and_the_finished_proof():
    loops, box, whole = finger()
    part = prove_factor_ranges(loops, box, max_boxes=1, partial=True, **CHEAP)
    assert part.boxes == 1 and 0.0 < part.done < 1.0 and whole.done == 1.0
    assert np.all(part.lower <= whole.lower) and np.all(part.upper >= whole.upper)
    assert np.any(part.upper > whole.upper) and np.any(part.lower < whole.lower)  # the work left is tightness
    problem = FactorProblem.from_loops(loops)
    rng = np.random.default_rng(41)
    q = rng.uniform(box.q_lower, box.q_upper, (400, problem.m))
    qd = rng.uniform(box.qdot_lower, box.qdot_upper, (400, problem.m))
    a = np.where(rng.integers(0, 2, (400, problem.m)) == 1, box.qddot_upper, box.qddot_lower)
    assert part.contains(problem.values(q, qd, a)).all()


def test_boxes_with_no_finite_enclosure_yet_come_first():
    # (q_lo, q_hi, v_lo, v_hi, open sides, volume share, parent's lower, parent's upper)
    sides = np.ones((1, 2, 3, 2), bool)
    finite = (np.zeros(2), np.ones(2), np.zeros(2), np.ones(2), sides, 0.5, np.zeros((1, 2, 3)), np.ones((1, 2, 3)))
    small = (np.zeros(2), np.ones(2), np.zeros(2), np.ones(2), sides, 1e-3, np.full((1, 2, 3), -np.inf),
             np.full((1, 2, 3), np.inf))  # fmt: skip
    stack = [small] + [finite] * proof.BATCH
    batch, rest = proof._next_batch(stack)
    # the tiny box whose parent's M_hat^-1 was not proved is taken before sixteen boxes of 500 times its share
    assert any(b is small for b in batch) and len(rest) == 1 and rest[0] is finite
