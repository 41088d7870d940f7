//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_stability_hpp__
#define __pinsettle_stability_hpp__

#include "pinsettle/forces.hpp"

namespace pinsettle
{

  /// \brief The kind of rest found: the sign pattern of the stiffness matrix's eigenvalues.
  enum class Stability
  {
    /// Not assessed.
    Unknown,
    /// Every eigenvalue positive beyond the tolerance: a small push comes back.
    Stable,
    /// None negative, some zero within the tolerance (e.g. an arm turning freely about a
    /// vertical axis).
    Neutral,
    /// A negative eigenvalue: a saddle or a maximum; a small push falls away.
    Unstable,
    /// Stable by its stiffness, but held by a ground contact that carries almost no force or
    /// sits at its friction cone's edge (GroundContact::marginal): a small push may lift or
    /// slide it. Only a final rest is marked so (ConstraintSet::describeRest).
    Marginal
  };

  /// \brief snake_case name: "unknown", "stable", "neutral", "unstable", "marginal".
  const char * toString(Stability stability);

  /// \brief The stiffness matrix at a configuration and what its eigenvalues say.
  struct StabilityReport
  {
    Stability verdict = Stability::Unknown;
    /// Smallest eigenvalue of the symmetric part of K (N m/rad or N/m).
    double min_eigenvalue = 0.;
    /// Largest absolute eigenvalue, the scale of the tolerance.
    double max_abs_eigenvalue = 0.;
    /// Eigenvalues within the tolerance of zero.
    int neutral_directions = 0;
    /// |eigenvalue| <= tolerance counts as zero.
    double tolerance = 0.;
    /// Eigenvalues in increasing order (dim model.nv).
    Eigen::VectorXd eigenvalues;
    /// Unit eigenvector of the smallest eigenvalue, a tangent direction (dim model.nv).
    Eigen::VectorXd softest_direction;
    /// The stiffness matrix K the verdict was drawn from (dim model.nv x model.nv; with loops,
    /// restricted to the motions they allow: dim mobility x mobility).
    Eigen::MatrixXd stiffness;
    /// The joint velocities K's coordinates stand for (dim model.nv x dim K): the identity
    /// without loops, an orthonormal basis of the allowed motions with them.
    Eigen::MatrixXd basis;
  };

  ///
  /// \brief The verdict from a stiffness matrix: eigenvalues of its symmetric part, zero within
  /// the larger of relative_tolerance times the largest absolute one and absolute_tolerance.
  ///
  /// \param[in] K Stiffness matrix (dim n x n); basis is set to the identity.
  /// \param[in] absolute_tolerance Eigenvalues this small count as zero whatever the largest
  ///            (N m/rad or N/m): where K vanishes altogether (wheels turning freely), its
  ///            eigenvalues are round-off of either sign (computeStiffnessFloor).
  ///
  StabilityReport assessStiffness(
    const Eigen::MatrixXd & K, double relative_tolerance, double absolute_tolerance = 0.);

  ///
  /// \brief The model's own scale of gravity's work, sum_i m_i |g| times the longest lever the
  /// model can have (the sum of its joints' offsets and the largest centre-of-mass offset), in
  /// J (or N m per rad): the size of the terms gravity's stiffness is summed from, hence of its
  /// round-off. 0 without gravity or mass.
  ///
  double computeGravityScale(const pinocchio::Model & model);

  /// \brief Round-off of a stiffness relative to computeGravityScale: double precision's 2.2e-16
  /// times a margin for the sums over the bodies (measured: a wheeled robot whose stiffness is
  /// zero gave eigenvalues of 8.9e-16 N m/rad of either sign at a scale of 150 J).
  constexpr double kStiffnessRoundOff = 1e-13;

  ///
  /// \brief The absolute tolerance of a verdict on this model: kStiffnessRoundOff times
  /// computeGravityScale (N m/rad or N/m), 1e6 times that when the stiffness is differenced
  /// (stiffnessByFiniteDifferences: a central difference of step 1e-6 divides the force's
  /// round-off by it).
  ///
  double computeStiffnessFloor(const pinocchio::Model & model, bool differenced);

  ///
  /// \brief Potential energy left to release before the rest the report describes:
  /// 1/2 f^T K^+ f with f = basis^T tau along the eigenvectors of K's symmetric part, each
  /// eigenvalue taken at least report.tolerance (a force along a neutral direction releases
  /// energy without bound, so it counts in full), in J. Zero at an exact rest; where the
  /// kinetic energy was quiet only because the mechanism hardly moved (a step halved many
  /// times), it stays large.
  ///
  /// \param[in] report A stable or neutral assessment (assessStability).
  /// \param[in] tau The static force at the assessed configuration (dim model.nv, N m or N).
  /// \return The energy (J); infinity where tau pulls along a direction of zero tolerance.
  ///
  double computeRestEnergy(const StabilityReport & report, const Eigen::VectorXd & tau);

  ///
  /// \brief Stiffness matrix K = d tau_static / dq, the Jacobian of the net static generalized
  /// force (computeStaticForce) along the tangent directions of the configuration space.
  ///
  /// Gravity comes from Pinocchio's analytic derivatives
  /// (pinocchio::computeGeneralizedGravityDerivatives), except on a model with a joint whose
  /// motion subspace varies with its own configuration (universal, ZYX spherical, ellipsoid,
  /// composite), where Pinocchio 4.1's derivatives drop that variation and gravity's part is
  /// differenced too; the applied efforts, when there are any, in closed form where the force
  /// model gives it (ForceModel::addStiffness: the force elements, unless a point element hangs
  /// below such a joint), else by central finite differences of their generalized force (step
  /// 1e-6 along each tangent direction, through pinocchio::integrate).
  /// stiffnessByFiniteDifferences says which.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] forces Applied efforts, or nullptr for gravity alone.
  /// \return K (dim model.nv x model.nv, N m/rad or N/m).
  ///
  Eigen::MatrixXd computeStiffnessMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Whether computeStiffnessMatrix differences (part of) K numerically: with applied
  /// efforts whose stiffness has no closed form (ForceModel::hasClosedFormStiffness), or on a
  /// model with a joint whose motion subspace varies with its configuration. A verdict then takes a
  /// tolerance of 1e-7 of the largest eigenvalue instead of 1e-9.
  ///
  bool stiffnessByFiniteDifferences(const pinocchio::Model & model, const ForceModel * forces);

  ///
  /// \brief Stability of a rest at q from the eigenvalues of the symmetric part of K.
  ///
  /// The tolerance is scale-aware: 1e-9 times the largest absolute eigenvalue with analytic
  /// derivatives alone, 1e-7 times it when finite differences took part (their error).
  ///
  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  /// \brief Time scales of the mechanism linearised at a configuration, for the automatic step.
  ///
  /// With stiff-mode scaling on, modes far stiffer than the rest (a 1e8 N/m spring on a 10 g body
  /// next to a 10 kg pendulum) get extra inertia so that their frequency drops to the level of
  /// the others: the mass matrix becomes M(q) + W^T diag(d) W with constant W and d (the modes'
  /// momenta and added masses at the estimate). That is still a mechanical system with the same
  /// potential, so its equilibria, their stability and its energy balance are those of the real
  /// one; only the stiff modes move more slowly, and the step follows the slow ones.
  struct TimeScale
  {
    /// Highest natural frequency the step must resolve (rad/s): the square root of the larger of
    /// max |eig(M^-1 K)| (K symmetrised; stiff modes at their scaled level) and
    /// max |M^-1 tau_static| per unit of joint motion (rad or m). The second term is the
    /// amplitude of a revolute joint's gravity torque A sin(theta): where K vanishes (an arm held
    /// horizontal) the pull itself still sets the time scale.
    double omega_max = 0.;
    /// The same without stiff-mode scaling (rad/s): what the explicit step alone would need.
    double omega_unscaled = 0.;
    /// Highest damping rate (1/s): max eig(M^-1 D), D = -d applied / d v (dampers only).
    double damping_rate = 0.;
    /// Stability limit of semi-implicit Euler on the linearised system (s):
    /// 4 / (damping_rate + sqrt(damping_rate^2 + 4 omega_max^2)), i.e. 2 / omega_max without
    /// damping; infinity when nothing pulls or damps (a free body at rest without gravity).
    double critical_step = 0.;
    /// Scaled stiff modes: W = Phi_s^T M at the estimate, Phi_s their M-orthonormal shapes
    /// (dim r x model.nv) ...
    Eigen::MatrixXd stiff_momenta;
    /// ... and their added masses d = |lambda| / target - 1 (dim r), target the level they
    /// are scaled down to.
    Eigen::VectorXd stiff_masses;
  };

  /// \brief Two clusters of modes count as apart when their eig(M^-1 K) differ by more than
  /// this factor (100x in frequency).
  constexpr double kStiffGap = 1e4;
  /// \brief Modes more than this factor above the softest one (about 30x in frequency) are
  /// scaled down to it even without a gap: a spread of masses or lengths (a light gripper at
  /// the end of an arm) bounds the steps per period of the slowest motion.
  constexpr double kStiffSpread = 1e3;
  /// \brief Scaling r stiff modes makes a step cost about
  /// 1 + kStiffCostBase + nv (1 + r) / kStiffCostScale times an unscaled one (the Woodbury
  /// correction's fixed cost, then an O(nv^2 (1 + r)) product on top of an O(nv)
  /// pinocchio::aba; measured on arms of 6 and 7 joints and chains of 50 to 300 links). The
  /// steps fall by about the square root of the step's gain, so modes are scaled only when
  /// the highest frequency drops by more than the square of that cost.
  constexpr double kStiffCostBase = 0.5;
  constexpr double kStiffCostScale = 2500.;

  ///
  /// \brief Time scales at q from the stiffness matrix K (computeStiffnessMatrix), the joint
  /// space inertia matrix M (pinocchio::crba) and the damping matrix D.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] forces Applied efforts, or nullptr for gravity alone.
  /// \param[in] scale_stiff_modes Find modes more than kStiffGap stiffer than every mode (and
  /// pull) below them and scale them down to that level (TimeScale::stiff_momenta,
  /// TimeScale::stiff_masses).
  /// \param[in] stiffness K at q when already known (dim model.nv x model.nv), else nullptr.
  ///
  TimeScale computeTimeScale(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr,
    bool scale_stiff_modes = false,
    const Eigen::MatrixXd * stiffness = nullptr);

  ///
  /// \brief Time scales of the linear system M a = tau - K x - D v from its matrices (the
  /// computation behind the model-based overload, also used on reduced coordinates).
  ///
  /// \param[in] K Stiffness (dim n x n); its symmetric part is used.
  /// \param[in] mass Inertia (dim n x n, symmetric positive definite).
  /// \param[in] tau Static force at the linearisation point (dim n), the pull.
  /// \param[in] damping Damping matrix D (dim n x n), or nullptr for none.
  ///
  TimeScale computeTimeScale(
    const Eigen::MatrixXd & K,
    const Eigen::MatrixXd & mass,
    const Eigen::VectorXd & tau,
    const Eigen::MatrixXd * damping,
    bool scale_stiff_modes);

  ///
  /// \brief Least-squares solution of K x = b with a rank cut: pivots below threshold times the
  /// largest are taken as zero, and x has no part along the directions they span (a Newton step
  /// that leaves neutral directions alone).
  ///
  /// \param[in] K Matrix (dim m x n).
  /// \param[in] b Right-hand side (dim m).
  /// \param[in] threshold Relative rank threshold (see Eigen::CompleteOrthogonalDecomposition).
  /// \return x (dim n), the minimum-norm least-squares solution on the kept rank.
  ///
  Eigen::VectorXd solveWithRankCut(
    const Eigen::MatrixXd & K, const Eigen::VectorXd & b, double threshold);

  ///
  /// \brief Damping matrix D = -d applied / d v at (q, 0) by central differences (the damper
  /// forces are linear in v); zero without dampers.
  ///
  /// \return D (dim model.nv x model.nv, N m s/rad or N s/m).
  ///
  Eigen::MatrixXd computeDampingMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces);

} // namespace pinsettle

#endif // ifndef __pinsettle_stability_hpp__
