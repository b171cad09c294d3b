"""Seed 003: switched observability (eqs. 6, 12), pole placement (A4), bank + detector + observer (8)-(10)."""

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_C, switched_paper_run, switched_training_runs
from pwas_hdl.systems.switched_observer import mode_scores, observer_gains, run_switched_observer, switched_observability_matrix


@pytest.mark.parametrize("dwells", [[1, 1, 1], [2, 2, 2], [34, 33, 33]])
def test_eq12_switched_observability_rank_is_2(dwells):
    O = switched_observability_matrix([1, 2, 3], dwells)
    assert O.shape == (sum(dwells), 2)
    assert np.linalg.matrix_rank(O) == 2          # eq. (12)
    # rows are C(theta_j) A(theta_{j-1}) ... A(theta_0)
    np.testing.assert_allclose(O[1], SWITCHED_C[0] @ SWITCHED_A[0] if dwells[0] > 1 else SWITCHED_C[1] @ SWITCHED_A[0])


def test_observability_rank_drops_on_a_single_sample_and_an_unobservable_pair():
    assert np.linalg.matrix_rank(switched_observability_matrix([2], [1])) == 1
    A = (np.diag([0.5, 0.7]),)
    C = (np.array([1.0, 0.0]),)
    assert np.linalg.matrix_rank(switched_observability_matrix([1], [10], A, C)) == 1
    with pytest.raises(InputError):
        switched_observability_matrix([4], [2])


def test_pole_placement_gains_of_a4():
    K = observer_gains((0.3, 0.4))
    np.testing.assert_allclose(K[0], [0.0588, 0.6312], atol=1e-4)   # seed_003.md A4
    np.testing.assert_allclose(K[1], [0.1582, 0.1368], atol=1e-4)
    np.testing.assert_allclose(K[2], [0.0655, 0.6145], atol=1e-4)
    for Ai, Ci, Ki in zip(SWITCHED_A, SWITCHED_C, K):
        np.testing.assert_allclose(np.sort(np.linalg.eigvals(Ai - np.outer(Ki, Ci)).real), [0.3, 0.4], atol=1e-9)


def test_known_mode_observer_converges_and_detector_finds_the_modes():
    d = switched_training_runs(1, 3000, seed=5)
    known = run_switched_observer(d.u, d.y, known_mode=d.mode)
    assert np.abs(known.x_hat[-200:] - d.z_true[-200:]).max() < 1e-6   # noise-free: the error dies out
    det = run_switched_observer(d.u, d.y)
    sc = mode_scores(d.mode, det.theta_hat)
    assert sc["accuracy"] > 0.8 and min(sc["f1"].values()) > 0.7
    # the open-loop bank (8) as printed: its models forget x0 (stable modes), so it detects as well
    lit = run_switched_observer(d.u, d.y, bank="literal")
    assert mode_scores(d.mode, lit.theta_hat)["accuracy"] > 0.8
    # paper replica: known-mode output MSE is the initial transient only (the order of Table 1's 0.0069)
    p = switched_paper_run()
    mse = np.mean((p.y[:, 0] - run_switched_observer(p.u, p.y, known_mode=p.mode).y_hat) ** 2)
    assert 0.001 < mse < 0.05


def test_observer_refuses_bad_arguments():
    with pytest.raises(InputError):
        run_switched_observer(np.ones(5), np.ones(4))
    with pytest.raises(InputError):
        run_switched_observer(np.ones(5), np.ones(5), bank="closed")
    with pytest.raises(InputError):
        run_switched_observer(np.ones(5), np.ones(5), known_mode=np.array([1, 2, 3, 4, 1]))
