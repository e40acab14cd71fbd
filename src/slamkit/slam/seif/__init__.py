"""SEIF SLAM: the sparse extended information filter (Thrun et al., IJRR 23(7–8), 2004;
*Probabilistic Robotics*, ch. 12), with known or unknown correspondences.

The belief over ``y = (x_r, m_1, …, m_L)`` (as in :mod:`slamkit.slam.ekf_slam`) is held in
information form, ``Ω = Σ⁻¹`` and ``ξ = Ω μ``, plus a running estimate of the mean ``μ``.
An entry ``Ω_ij`` is a direct link between two variables; the filter keeps the robot linked
to at most ``max_active`` landmarks (the *active* ones), so each step touches the robot, the
active landmarks and what they are linked to — a cost set by ``max_active``, not by ``L``.

Every formula is derived here; ``F_x`` selects the pose, ``G``, ``V`` are the motion
Jacobians and ``R_x = V Q V_ᵀ`` the motion noise in pose space (3 × 3, rank 2 for a
unicycle: never inverted).

Motion (:func:`seif_motion_update`)
-----------------------------------
Linearised, ``y' = A y + c + F_xᵀ w`` with ``A = diag(G, I)``, so
``Σ' = A Σ Aᵀ + F_xᵀ R_x F_x`` and, with ``Φ = A⁻ᵀ Ω A⁻¹`` (the information after the
deterministic part; it changes only the pose rows and columns: ``Φ_xx = G⁻ᵀ Ω_xx G⁻¹``,
``Φ_xm = G⁻ᵀ Ω_xm``), Woodbury gives::

    Ω' = (Φ⁻¹ + F_xᵀ R_x F_x)⁻¹ = Φ − κ,   κ = Φ F_xᵀ R_x (I + Φ_xx R_x)⁻¹ F_x Φ

(using ``(R⁻¹ + B)⁻¹ = R (I + B R)⁻¹``, which needs no ``R⁻¹``). ``Φ F_xᵀ`` is nonzero only
in the rows of the robot and the active landmarks, so both terms live in that block.
The mean moves by ``δ = g(μ_x, u) − μ_x`` and the information vector keeps
``ξ − Ω μ`` unchanged (the mean estimate need not be exact)::

    μ' = μ + F_xᵀ δ,    ξ' = ξ + (Ω' − Ω) μ + Ω' F_xᵀ δ

The steps between two scans compose into one of the same form (``G = G₂ G₁``,
``R_x = G₂ R₁ G₂ᵀ + R₂``; :class:`~slamkit.slam.seif.kernels.PendingMotion`): the mean moves
at every control, the information once per scan.

Measurement (:func:`seif_measurement_update`)
---------------------------------------------
With ``H`` the 5-column Jacobian at ``μ`` and ``ν = z ⊖ h(μ)``, the linearised reading is
``z ≈ h(μ) + H (y − μ)``, i.e. ``z̃ = ν + H μ = H y + noise``; adding its information::

    Ω ← Ω + Hᵀ R⁻¹ H,    ξ ← ξ + Hᵀ R⁻¹ (ν + H μ)

(only the robot and landmark blocks), which makes the landmark active.

Sparsification (:func:`seif_sparsify`)
--------------------------------------
To deactivate ``m0`` (keeping ``m+`` active; ``m-`` the rest) SEIF replaces
``p(x | m0, m+)`` by ``p(x | m+, m- = 0)``: the approximation
``p̃(y) = p(x | m+, m- = 0) p(m0, m+, m-)``. In information form, with ``Ω₀`` the block of
``Ω`` on ``(x, m+, m0)`` (= the information of ``p(x, m0, m+ | m-)``):

* ``p(m0, m+, m-)``: the pose marginalised out, ``Ω − Ω F_x Ω_xx⁻¹ F_xᵀ Ω = Ω − Ω³``;
* ``p(x, m+ | m-)``: ``m0`` marginalised out of ``Ω₀``: ``Ω₀ − Ω₀ F_0 (Ω₀)_00⁻¹ F_0ᵀ Ω₀
  = Ω₀ − Ω¹``; ``p(m+ | m-)``: ``(x, m0)`` marginalised: ``Ω₀ − Ω²``; their quotient
  ``p(x | m+, m-)`` has information ``Ω² − Ω¹``;

so ``Ω̃ = Ω − Ω¹ + Ω² − Ω³``, in which the robot–``m0`` links are exactly zero, and
``ξ̃ = ξ + (Ω̃ − Ω) μ`` keeps the mean. All four terms live in the ``(x, m+, m0)`` block.

Mean recovery
-------------
``μ = Ω⁻¹ ξ`` is not computed. Each step relaxes the pose, the active landmarks and a few
others in turn (block Gauss–Seidel, amortised): ``μ_i ← Ω_ii⁻¹ (ξ_i − Σ_{j≠i} Ω_ij μ_j)``
over the blocks ``j`` linked to ``i``. :meth:`Seif.finish` solves ``Ω μ = ξ`` exactly once
and reports the landmark marginals from ``Ω⁻¹``.

Data association (:mod:`~slamkit.slam.seif.association`)
--------------------------------------------------------
Readings without ids are paired by maximum likelihood, as EKF-SLAM's nearest neighbour does,
but SEIF has no covariance at hand. For a reading ``z`` and a candidate landmark ``j`` the
innovation ``ν = z ⊖ h(μ_x, μ_j)`` (at the running mean) has covariance
``S = H Σ_(x,j) Hᵀ + R``, ``H`` the 5-column Jacobian and ``Σ_(x,j)`` the 5 × 5 marginal
covariance of ``(x, m_j)`` — a block of ``Ω⁻¹``, which is not formed. Split the state into
a *blanket* ``B ∋ x, m_j`` and the rest ``C``. The rows of ``Ω`` on ``B`` are the information
of ``p(y_B | y_C)``, so ``Ω_BB⁻¹`` is the covariance of ``y_B`` *given* ``y_C``; by the law of
total covariance ``Σ_BB = Ω_BB⁻¹ + Cov(E[y_B | y_C]) ⪰ Ω_BB⁻¹``. Conditioning on the rest
gives a lower bound that is exact when ``B`` has no link to ``C`` (``Ω_BC = 0``) and that
grows towards the marginal as ``B`` grows (for ``B ⊂ B'`` the same argument inside ``B'``
gives ``(Ω_B'B'⁻¹)_BB ⪰ Ω_BB⁻¹``). The links of the landmarks far from ``B`` are weak
(sparsification keeps the robot linked to a few), so a blanket of the variables linked to
``x`` and ``m_j`` — their Markov blanket — already holds most of the correlation.

Per scan, the candidates are the landmarks within ``candidate_radius`` of the point a
reading places (at most ``max_candidates``); ``B`` = the robot, the candidates, the active
landmarks (the robot's neighbours) and the candidates' neighbours (``blanket_hops`` rings of
links, at most ``max_blanket`` landmarks), so its size is bounded by the configuration and
the links, not by the map. One Cholesky factorisation of ``Ω_BB``, solved for the columns of
the robot and the candidates, gives every ``Σ_(x,j)`` of the scan. Then
``d²_kj = ν_kjᵀ S_kj⁻¹ ν_kj``; readings and candidates are paired greedily by increasing
``d²`` inside the gate ``χ²_m(gate_probability)``, and an unpaired reading starts a landmark
if its ``d²`` to every candidate exceeds ``χ²_m(new_landmark_probability)`` (else it is
rejected). The landmark search itself is a vectorised distance test over the landmark
means, ``O(L)`` with a tiny constant.

The heading is kept unwrapped inside the filter (``ξ = Ω μ`` is linear in it); estimates
are reported wrapped.

The package, by concern: :mod:`~slamkit.slam.seif.state` (the buffers of ``Ω``, ``ξ``,
``μ`` and the links), :mod:`~slamkit.slam.seif.kernels` (motion update, measurement update,
sparsification), :mod:`~slamkit.slam.seif.association`, :mod:`~slamkit.slam.seif.recovery`
(mean recovery), :mod:`~slamkit.slam.seif.config` and the estimator shell
:class:`Seif` (:mod:`~slamkit.slam.seif.estimator`).
"""

from slamkit.slam.seif.config import SeifConfig
from slamkit.slam.seif.estimator import Seif
from slamkit.slam.seif.kernels import seif_measurement_update, seif_motion_update, seif_sparsify

__all__ = [
    "Seif",
    "SeifConfig",
    "seif_measurement_update",
    "seif_motion_update",
    "seif_sparsify",
]
