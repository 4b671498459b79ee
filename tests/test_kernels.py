"""The compiled kernels (_kernels.py); their loop against the Python reference loop: test_simulation.py."""

import numpy as np


def test_log_rows_have_one_named_index_per_column():
    """The loops write rows through ``LOG_*`` names (``record_tick``); each name is its column."""
    from tire_learning_env import _kernels as K

    assert [getattr(K, "LOG_" + name.upper()) for name in K.LOG_COLUMNS] == list(range(K.N_LOG))
    assert K.LOG_INDEX == {name: i for i, name in enumerate(K.LOG_COLUMNS)}
    values = dict(t=1.0, delta=2.0, vx=3.0, ax=4.0, kappa=5.0, psi_dot_des=6.0, psi_ddot_des=7.0, e1=8.0, e2=9.0,
                  yaw_rate=10.0, ay=11.0, true_e1=12.0, true_e1_dot=13.0, true_e2=14.0, true_e2_dot=15.0,
                  alpha_f=16.0, alpha_r=17.0, Fyf=18.0, Fyr=19.0, s=20.0)  # fmt: skip
    for delivered in (True, False):
        out = np.full((2, K.N_LOG), -1.0)
        K.record_true_state(out, 1, np.array([values[k] for k in ("true_e1", "true_e1_dot", "true_e2", "true_e2_dot")] + [0.0, 0.0]))
        K.record_tick(out, 1, *(values[k] for k in ("t", "delta", "vx", "ax", "kappa", "psi_dot_des", "psi_ddot_des")),
                      delivered, values["e1"], values["e2"],
                      *(values[k] for k in ("yaw_rate", "ay", "alpha_f", "alpha_r", "Fyf", "Fyr", "s")))  # fmt: skip
        row = dict(zip(K.LOG_COLUMNS, out[1]))
        assert np.all(out[0] == -1.0)
        if not delivered:  # no frame delivered: NaN camera columns
            assert np.isnan(row.pop("e1")) and np.isnan(row.pop("e2"))
        assert row == {k: values[k] for k in row}
