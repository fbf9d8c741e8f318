"""Simulation-error (output-error) refinement of ARX-structured models, PWA and linear.

Least squares on eq. (3)'s one-step error fits what a model predicts one sample ahead; a free
run feeds the model its own outputs, and small one-step errors can add up. Refinement starts
from the fitted parameter matrices θ_i and minimises the free-run error over the training
experiments,

    J(θ) = Σ_e Σ_{k ≥ w} ‖ y_e(k) − ŷ_e(k; θ) ‖²,   ŷ_e(k) = θ_{λ(k)}ᵀ φ̂_e(k),

where φ̂ holds the simulated past outputs and λ(k) is the region (step 6) of φ̂_e(k), kept
fixed as a function of φ: the hyperplanes do not move, the regions visited follow the run.

The free run may buy its accuracy with the one-step prediction (on the robot, a joint's
own-increment coefficient moved from 1.0 to −0.9 and the one-step error grew seventy-fold).
With a one-step weight w > 0 the refinement minimises instead

    J_w(θ) = J(θ) + w · J(θ₀) / J₁(θ₀) · J₁(θ),
    J₁(θ) = Σ_e Σ_k ‖ y_e(k) − θ_{λ(k)}ᵀ φ_e(k) ‖²,

J₁ the one-step (equation) error of eq. (3) on the measured regressors φ — the least-squares
objective — with λ(k) the region of the measured φ_e(k), both costs as means per sample and
output. The ratio at the start θ₀ makes w dimensionless: with w = 1, raising the one-step
error by its starting value costs as much as raising the free-run error by its starting value.
Since J₁(θ) = J₁(θ_LS) + (θ − θ_LS)ᵀ XᵀX (θ − θ_LS) / n for the least-squares solution θ_LS
(X the stacked regressors), the term is a regularisation towards least squares in the metric
of the one-step error: directions that barely change the one-step prediction stay free.
w = 0 is the free-run refinement alone; as w grows, the minimiser tends to θ_LS (the start,
when the start is least squares). The iterate is then chosen on J_w of the held-out
experiments (their own ratio at θ₀).

The minimiser is Levenberg–Marquardt on the normal equations. The Jacobian of the free run
is propagated forward in time (sensitivities dŷ(k)/dθ through the output lags of φ̂, the
region treated as locally constant), for all experiments at once, and only JᵀJ (P × P) and
Jᵀr are kept, never J itself (N·m × P: hundreds of MB on a long record). J₁'s
residuals are linear in θ, so its JᵀJ is computed once.

The package holds the free run and its sensitivities (`simulator`), the costs J, J₁ and
J_w (`objective`), Levenberg–Marquardt on them (`solver`) and the step object
(`estimator`).
"""

from .estimator import VALIDATION_FRACTION, OutputErrorRefinement, held_out, numbered
from .objective import OneStepError, RefinementErrors
from .simulator import FreeRuns, OutputFreeRuns
from .solver import OutputErrorResult, levenberg_marquardt, refine_output_error, refine_outputs

__all__ = ["VALIDATION_FRACTION", "FreeRuns", "OneStepError", "OutputErrorRefinement",
           "OutputErrorResult", "OutputFreeRuns", "RefinementErrors", "held_out", "numbered",
           "levenberg_marquardt", "refine_output_error", "refine_outputs"]
