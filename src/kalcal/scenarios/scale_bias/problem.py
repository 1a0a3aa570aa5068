"""The scale/bias filter as a verification problem: theta drawn from the prior, h_k = [z_k, 1] per realization.

The filter's gains depend on the data (through z_k), so every realization carries its own P_k and S_k:
the NEES and NIS are normalized by them, the covariance and orthogonality checks test the errors
whitened by each realization's own P_k (eps = L_k^-1 e_k, N(0, I) for a filter whose model is right;
the mean of P_k is no valid reference when P varies), and the whiteness check the innovations
normalized by each realization's own S_k.

The one departure from the filter's model that the truth keeps on purpose is *errors in variables*: the
regressor h_k = [z_k, 1] holds the noisy reading z_k = zeta_k - nu_k, and the same nu_k enters the
measurement noise w_k = eta_k + theta1 nu_k, so E[h_k^T w_k] = [-theta1 sigma_nu^2, 0] is not zero.
:func:`eiv_mean_error` predicts the mean error this causes, to first order in sigma_nu^2. (With
``scenario.excitation = "reference"`` the regressors also depend on theta, a second departure that the
prediction leaves out; see docs/scale-bias.md.)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from kalcal.core.steps import gain_and_covariance, nis, predict_covariance
from kalcal.scenarios.scale_bias.filter import filter_scale_bias, regressors
from kalcal.scenarios.scale_bias.settings import MEASUREMENT_NAMES, STATE_NAMES, ScaleBiasScenario
from kalcal.montecarlo.accumulators import BlockResult, MomentSums, SumBuffers
from kalcal.montecarlo.problem import ProblemDefaults, ProblemInfo, check_engine
from kalcal.scenarios.scale_bias.simulation import normals_per_realization, sample_scale_bias


def problem_info(scenario: ScaleBiasScenario) -> ProblemInfo:
    """State names theta1 (1) and theta2 (signal unit); the measurement is the reference."""
    unit = scenario.scenario.unit
    return ProblemInfo(
        scenario=scenario.NAME,
        update_times=scenario.scenario.sample_times(),
        state_names=STATE_NAMES,
        state_units=scenario.state_units,
        measurement_names=MEASUREMENT_NAMES,
        measurement_units=(unit,),
        capabilities=scenario.capabilities,
    )


def mean_regressor_signal(scenario: ScaleBiasScenario) -> np.ndarray:
    """The sensor's noise-free reading zeta_k at the truth's prior mean of theta, (K,).

    Exactly zeta_k for ``excitation = "sensor"``; for ``"reference"``, (s_k - theta2) / theta1 at the
    mean theta (the regressors then vary with theta, which the prediction ignores).
    """
    profile = scenario.profile(scenario.scenario.sample_times())
    if scenario.scenario.excitation == "sensor":
        return profile
    theta1, theta2 = scenario.truth_prior().mean
    return (profile - theta2) / theta1


def eiv_mean_error(scenario: ScaleBiasScenario) -> np.ndarray:
    """E[theta_k - xhat_k^+], the mean error of the filter, to first order in sigma_nu^2, shape (K, 2).

    Two sources: a prior mean that differs from the truth's, m_0 = E[theta_0] - x_0^+, which the filter
    shrinks as m_k = (I - K_k h_k) m_{k-1}; and errors in variables. Write h_k = hbar_k - nu_k e1^T with
    hbar_k = [zeta_k, 1], c = E[theta1] sigma_nu^2 (truth's), and let the filter's P_k^-, S_k, K_k,
    L_k = I - K_k hbar_k be those on the noise-free regressors. Expanding the error recursion
    e^+ = (I - K h) e^- - K w to second order in nu (the terms with eta and theta average out):

        m_k = L_k m_{k-1} - L_k u_k / S_k + (c / S_k) P_k^- (e1 - 2 hbar_k^T (hbar_k P_k^- e1) / S_k)

    The last term is -E[K_k w_k]: the gain and the noise share nu_k. The middle one is
    -E[d(K_k h_k) eps_{k-1}] with u_k = E[pi_k hbar_k^T hbar_k eps_{k-1}]: the first-order perturbation
    pi_k of P_k^- by past nu_j is correlated with the part eps of the error they caused. The cross moment
    C_k = E[pi_k (x) eps_k], (2, 2, 2), follows C_k = L (x) L (x) L C_{k-1} - c D_k (x) K_k, where
    D_k = dP_k^+ / d nu_k = (P e1 hbar P + P hbar^T e1^T P) / S - 2 (P hbar^T hbar P) (e1^T P hbar^T) / S^2
    at P = P_k^-. For Q = 0 this agrees with the batch least-squares expansion
    P_k [(k - 3 + tr(P_0^{-1} P_k)) e1 + P_0^{-1} P_k e1] c / R to O(sigma_nu^4).
    """
    f_prior = scenario.filter_prior()
    t_prior = scenario.truth_prior()
    r = scenario.filter_noise_variance()
    q = scenario.filter_process_noise()
    c = float(t_prior.mean[0]) * scenario.truth.sensor_noise_std**2
    zeta = mean_regressor_signal(scenario)
    e1 = np.array([1.0, 0.0])
    eye = np.eye(2)
    mean = t_prior.mean - f_prior.mean
    cross = np.zeros((2, 2, 2))  # C[a, b, c] = E[pi_ab eps_c]
    cov = f_prior.cov
    out = np.empty((zeta.size, 2))
    v = np.array([[r]])
    for k, z in enumerate(zeta):
        cov = predict_covariance(cov, None, q)
        h = np.array([z, 1.0])
        ph = cov @ h
        # K_k, S_k and the Joseph-form P_k^+ of the reference step, on the noise-free regressor
        gain_col, posterior, s_mat = gain_and_covariance(cov, h[None, :], v, "joseph")
        gain, s = gain_col[:, 0], float(s_mat[0, 0])
        lk = eye - np.outer(gain, h)
        u = np.einsum("abc,b,c->a", cross, h, h)
        pe1 = cov @ e1
        mean = lk @ mean - lk @ u / s + (c / s) * (pe1 - 2.0 * ph * (ph @ e1) / s)
        d = (np.outer(pe1, ph) + np.outer(ph, pe1)) / s - 2.0 * np.outer(ph, ph) * (ph @ e1) / s**2
        cross = np.einsum("ai,bj,ck,ijk->abc", lk, lk, lk, cross) - c * d[:, :, None] * gain[None, None, :]
        cov = posterior
        out[k] = mean
    return out


def model_error_cause(scenario: ScaleBiasScenario) -> str:
    """A sentence naming what makes the truth depart from the filter's model, for check details."""
    s, t = scenario.scenario, scenario.truth
    f = scenario.filter_settings
    zeta = mean_regressor_signal(scenario)
    spread = float(np.var(zeta))
    theta1 = float(scenario.truth_prior().mean[0])
    causes = []
    if t.sensor_noise_std > 0:
        attenuation = theta1 * t.sensor_noise_std**2 / (spread + t.sensor_noise_std**2) if spread > 0 else float("nan")
        causes.append(
            "errors in variables (the regressor h_k = [z_k, 1] holds the noisy sensor reading, and its noise nu_k, "
            f"sigma_nu = {t.sensor_noise_std:g}, also enters w_k = eta_k + theta1 nu_k: that attenuates theta1 by "
            f"about theta1 sigma_nu^2 / (var(zeta) + sigma_nu^2) = {attenuation:.3g}, var(zeta) = {spread:.4g})"
        )
    if s.excitation == "reference":
        causes.append(
            "regressors that depend on theta (the excitation is psi itself, so z_k = (psi_k - theta2) / theta1 - nu_k "
            "carries information about theta that the filter ignores: a mean error of order std(theta1) / theta1 "
            "filter sigmas while the prior still counts, not included in the prediction)"
        )
    if (f.scale_error, f.bias) != (t.scale_error, t.bias):
        causes.append("the filter's prior mean differing from the truth's")
    return " and ".join(causes)


@dataclass(frozen=True)
class ScaleBiasProblem(ProblemDefaults):
    """The scale/bias filter against realizations drawn from its scenario (engine "exact" only).

    Per-sample simulation is already exact here (every sample is a measurement), so there is no separate
    "sampled" engine. ``form`` defaults to the scenario's ``filter.form``; ``residual_pairs=False`` skips
    the sums of r_k r_j over all pairs of samples (and so the whiteness check).
    """

    #: why this filter has no steady state (kalcal.reporting.steady_state)
    NOT_TIME_INVARIANT: ClassVar[str] = (
        "its measurement row h_k = [z_k, 1] holds the sensor's reading, so it changes at every sample and the "
        "gains depend on the data: the filter is not time-invariant and there is no algebraic Riccati equation"
    )

    scenario: ScaleBiasScenario
    form: str | None = None
    residual_pairs: bool = True
    info: ProblemInfo = field(init=False)
    engines: tuple[str, ...] = field(init=False, default=("exact",))

    def __post_init__(self) -> None:
        object.__setattr__(self, "info", problem_info(self.scenario))

    def steady_state_reason(self) -> str:
        """Its measurement row changes at every sample (:attr:`NOT_TIME_INVARIANT`)."""
        return self.NOT_TIME_INVARIANT

    def normals_per_realization(self, engine: str) -> int:
        return normals_per_realization(self.scenario)

    def run_block(self, rng: np.random.Generator, n: int, engine: str) -> BlockResult:
        """Simulate n realizations and run the filter on each, with its own h_k, P_k and S_k."""
        check_engine(self, engine)
        samples = sample_scale_bias(self.scenario, rng, n)
        run = filter_scale_bias(self.scenario, samples.reference, samples.sensor, self.form)
        error = samples.theta - run.posterior
        # e^T P^{-1} e by a solve per realization and sample
        nees = np.einsum("nki,nki->nk", error, np.linalg.solve(run.cov, error[..., None])[..., 0])
        return BlockResult(
            error=error,
            estimate=run.posterior,
            residual=run.residual[..., None],
            nees=nees,
            nis=nis(run.residual[..., None], run.innovation_var[..., None, None]),
            filter_cov_sum=run.cov.sum(axis=0),
            filter_cov=run.cov,
        )

    def shown_realization(
        self, rng: np.random.Generator, n: int, index: int, engine: str = "exact"
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Realization ``index`` of a block of n drawn from ``rng``: its error, estimate and own P, (K, 2),
        (K, 2), (K, 2, 2), the values of ``run_block``'s bit for bit (each series is filtered on its own).

        The block is drawn whole (its draws are interleaved across its realizations) and only this series
        is filtered: 0.05-0.13 s against 0.9-2.4 s for the block's 4096.
        """
        check_engine(self, engine)
        if not 0 <= index < n:
            raise ValueError(f"realization index must lie in [0, {n}), got {index}")
        samples = sample_scale_bias(self.scenario, rng, n)
        one = slice(index, index + 1)
        run = filter_scale_bias(self.scenario, samples.reference[one], samples.sensor[one], self.form)
        return (samples.theta[index] - run.posterior[0], run.posterior[0], run.cov[0])

    def block_sums(self, rng: np.random.Generator, n: int, engine: str) -> MomentSums:
        """The moment sums of ``run_block`` (same draws), filtered and summed in one compiled pass.

        ``MomentSums.from_block(self.run_block(rng, n, engine))`` is the numpy oracle of the tests.
        """
        from kalcal.scenarios.scale_bias.kernels import regression_block_moments  # numba: loaded by the runs

        check_engine(self, engine)
        samples = sample_scale_bias(self.scenario, rng, n)
        prior = self.scenario.filter_prior()
        sums = SumBuffers.zeros(samples.time.size, 2, 1, n, self.residual_pairs, own_cov=True)
        regression_block_moments(
            np.ascontiguousarray(samples.reference),
            np.ascontiguousarray(regressors(samples.sensor)),
            samples.theta,  # constant parameters: a view broadcast along K, read as it is (a copy was 20 MB a block)
            prior.mean,
            prior.cov,
            float(self.scenario.filter_noise_variance()),
            self.scenario.filter_process_noise(),
            (self.form or self.scenario.filter_settings.form) == "joseph",
            sums,
        )
        return MomentSums.from_buffers(n, sums)

    def expected_mean_error(self) -> np.ndarray:
        """The mean error predicted by errors in variables and any prior-mean offset, (K, 2)."""
        return eiv_mean_error(self.scenario)
