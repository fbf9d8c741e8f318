"""Regions given by the user: the signs of scheduling variables, linear combinations of φ.

A machine's modes are often known in advance: Coulomb friction changes sign with a joint's
velocity, so the sign of the output's increment y_j(k−1) − y_j(k−2) decides the mode. Such a
variable z(k) = wᵀφ(k) is a linear combination of the regressor of eq. (2)–(3); v variables
give 2^v regions, region Σ_v 2^v [z_v(k) > 0]. These regions replace steps 2–6 of the paper
(local models, clustering, sub-models, SVM) when a [`PWARX`][pwa_pipeline.PWARX] is given
``scheduling=``; the sub-models are then fitted by least squares on the rows of each region.
"""

from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval, StrOptions

from .._typing import Float2D

#: Which parameters differ between the scheduled regions.
SWITCHES = ("all", "offset", "continuous", "select")


class SignScheduling(BaseEstimator):
    """Regions from the signs of scheduling variables z = wᵀφ (see the module doc).

    Parameters
    ----------
    variables : "own_increment" or list of dict, default "own_increment"
        ``"own_increment"``: for each output j its own increment y_j(k−1) − y_j(k−2), so each
        output has two regions (moving up or down; the robot's velocity sign). Otherwise a
        list of combinations shared by every output, each a dict from regressor names (as in
        `regressor_names` with outputs ``y1, y2, …`` and inputs
        ``u1, u2, …``, e.g. ``{"y1(k-1)": 1.0, "y1(k-2)": -1.0}``) to coefficients.
    switch : {"all", "offset", "continuous", "select"}, default "all"
        ``"all"``: every parameter of a sub-model differs between regions; ``"offset"``:
        only the constant term does (a sign-dependent offset, Coulomb friction; needs
        ``affine=True``); ``"continuous"``: one linear model plus a hinge γ_v max(0, z_v)
        per variable, a PWA map continuous across every boundary, whose slopes bend there
        (a smooth nonlinearity; a threshold is the variable ``{"y1(k-1)": 1.0, "1": -4.7}``);
        ``"select"``: per output, whichever of one linear model, ``"offset"`` and ``"all"``
        has the lowest free-run error on the held-out training experiments (needs
        ``outputs="decoupled"``).
    min_gain : float, default 0.01
        With ``"select"``: a richer structure (``"offset"`` over linear, ``"all"`` over
        the structure kept so far) is kept only when it lowers the held-out free-run error
        by at least this fraction, so that noise does not decide.

    Examples
    --------
    >>> from pwa_pipeline.pwa.scheduling import SignScheduling
    >>> s = SignScheduling(variables=[{"y1(k-1)": 1.0, "y1(k-2)": -1.0}])
    >>> s.weights(0, ["y1(k-1)", "y1(k-2)", "u1(k-1)"], lags=2)
    array([[ 1., -1.,  0.]])
    """

    _parameter_constraints: dict = {
        "variables": [StrOptions({"own_increment"}), list],
        "switch": [StrOptions(set(SWITCHES))],
        "min_gain": [Interval(Real, 0, 1, closed="left")],
    }

    def __init__(self, variables: str | list[dict] = "own_increment", switch: str = "all",
                 min_gain: float = 0.01):
        self.variables = variables
        self.switch = switch
        self.min_gain = min_gain

    def weights(self, output: int, names: list[str], lags: int) -> Float2D:
        """The rows w_v of output ``output``'s scheduling variables over φ's entries.

        Parameters
        ----------
        output : int
            Output index j.
        names : list of str
            φ's entry names (`regressor_names` with ``y1…``, ``u1…``).
        lags : int
            Output lags in φ.

        Raises
        ------
        ValueError
            For an unknown regressor name, an empty or non-numeric combination, or
            ``"own_increment"`` with fewer than two output lags.
        """
        if self.variables == "own_increment":
            if lags < 2:
                raise ValueError(
                    f"scheduling on the own increment y(k-1) - y(k-2) needs two output lags "
                    f"in φ; φ has {lags} (use na >= 2, or form='velocity' with na >= 1)")
            combos = [{f"y{output + 1}(k-1)": 1.0, f"y{output + 1}(k-2)": -1.0}]
        else:
            combos = self.variables
        if not combos:
            raise ValueError("scheduling needs at least one variable")
        w = np.zeros((len(combos), len(names)))
        for v, combo in enumerate(combos):
            if not isinstance(combo, dict) or not combo:
                raise ValueError(f"scheduling variable {v} must be a non-empty table of "
                                 f"regressor name = coefficient, got {combo!r}")
            for name, coef in combo.items():
                if name not in names:
                    raise ValueError(f"scheduling variable {v}: unknown regressor {name!r}; "
                                     f"φ has {names}")
                if isinstance(coef, bool) or not isinstance(coef, int | float):
                    raise ValueError(f"scheduling variable {v}: coefficient of {name!r} must "
                                     f"be a number, got {coef!r}")
                w[v, names.index(name)] = coef
        return w
