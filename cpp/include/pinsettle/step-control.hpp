//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_step_control_hpp__
#define __pinsettle_step_control_hpp__

#include "pinsettle/loops.hpp"
#include "pinsettle/settings.hpp"
#include "pinsettle/stability.hpp"

#include <Eigen/Cholesky>

#include <cstdint>

namespace pinsettle
{

  ///
  /// \brief One step of semi-implicit Euler on the configuration manifold:
  /// v += h a, then q_next = integrate(q, h v).
  ///
  /// \param[in] q The configuration (dim model.nq).
  /// \param[in,out] v The joint velocity (dim model.nv).
  /// \param[in] a The joint acceleration (dim model.nv).
  /// \param[in] h The time step (s).
  /// \param[out] dq The tangent motion h v of the step (dim model.nv).
  /// \param[out] q_next The new configuration (dim model.nq).
  ///
  void integrateSemiImplicitEuler(
    const pinocchio::Model & model,
    const Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    const Eigen::VectorXd & a,
    double h,
    Eigen::VectorXd & dq,
    Eigen::VectorXd & q_next);

  ///
  /// \brief Fictitious joint inertias that bring every joint's own rate down towards the
  /// slowest one's (dynamic relaxation's masses, kept diagonal so that pinocchio::aba carries
  /// them as armature at no cost per step): a_i = r_i / omega_t^2 - M_ii, where a joint's rate
  /// r_i = max(|K_ii|, |tau_i|) is its stiffness or its pull (N m per rad against N m, a radian
  /// the length scale, as in computeTimeScale) and omega_t^2 the smallest r_i / M_ii, kept
  /// within kJointInertiaSpread of the largest.
  ///
  /// Near a stable rest r_i = K_ii and, by the Rayleigh quotient, K_ii / M_ii is at least the
  /// smallest eigenvalue of M^-1 K: the slowest mode is not slowed, the faster joints are. Far
  /// from one the pull sets the rate (a chain held horizontal has no stiffness at all). Rates
  /// below kJointRateFloor of the largest are round-off: those joints get nothing.
  ///
  /// \param[in] K The stiffness matrix (model.nv x model.nv, N m/rad or N/m).
  /// \param[in] mass_diagonal The diagonal of the mass matrix (dim model.nv, kg m^2 or kg).
  /// \param[in] tau The static generalized force (dim model.nv, N m or N).
  /// \return The added inertia per velocity coordinate (dim model.nv, kg m^2 or kg, >= 0).
  ///
  Eigen::VectorXd computeJointInertia(
    const Eigen::MatrixXd & K, const Eigen::VectorXd & mass_diagonal, const Eigen::VectorXd & tau);

  /// Largest ratio of the fastest joint's squared rate to the target's (computeJointInertia):
  /// a near-neutral joint must not slow the others a thousandfold (measured: 1e2 keeps chains
  /// of 200 links unequalised, 1e4 and more slow the xArm7 2.4-fold).
  constexpr double kJointInertiaSpread = 1e3;
  /// Rates below this fraction of the largest are round-off (computeJointInertia).
  constexpr double kJointRateFloor = 1e-9;

  ///
  /// \brief The step-size control: a fixed step, or the automatic one with its re-estimates and
  /// the scaling of stiff modes.
  ///
  /// The automatic step is dt_safety times the stability limit of the mechanism linearised where
  /// it is (computeTimeScale), estimated at the start and again once the configuration has moved
  /// kFarMove since the last estimate (not sooner than a window later); it grows at most
  /// twofold per estimate, since an estimate is local too. Each step is further bounded so that
  /// no joint turns more than dt_safety (rad or m): velocity-dependent forces stiffen fast
  /// motion, which the stiffness matrix does not see. With stiff-mode scaling, the modes far
  /// stiffer than the rest get a constant added inertia (TimeScale::stiff_masses): the solver
  /// corrects each acceleration for it (correctAcceleration) and counts its kinetic energy
  /// (addedEnergy). A roll-back halves the step for the rest of the run.
  ///
  /// Its memory is sized once per model and per estimate; a step allocates nothing.
  ///
  class StepController
  {
  public:
    /// Distance (rad or m, max norm) moved since the last estimate that calls for a new one.
    static constexpr double kFarMove = 0.1;
    /// Automatic step when nothing pulls, pushes or damps (its value does not matter then).
    static constexpr double kRestStep = 1e-3;
    /// Growth of the automatic step per step between damping events (Settings::dt_growth).
    static constexpr double kStepGrowthRate = 1.05;

    /// \param[in] loops Loop closures of the model (they must outlive the controller), or
    ///            nullptr.
    /// \param[in] stiff_modes Whether the constraints let stiff modes be slowed (not with
    ///            ground contacts: their impulses use the mass matrix, not the slowed modes').
    ///            Without it the joint inertia is not given by default either
    ///            (effectiveJointInertia).
    StepController(
      const pinocchio::Model & model, const LoopConstraints * loops, bool stiff_modes = true);

    ///
    /// \brief Start a run with the settings' step (a fixed one, or none yet for the automatic
    /// step: call estimate).
    ///
    /// \param[in] forces Applied efforts of the run, or nullptr.
    ///
    void start(const Settings & settings, const ForceModel * forces);

    /// \brief Whether the step is automatic (Settings::dt = 0).
    bool isAutomatic() const
    {
      return automatic_;
    }

    ///
    /// \brief A new estimate of the automatic step at q.
    ///
    /// The scaled stiff modes change the kinetic energy at the same velocity; an estimate never
    /// lets that add energy (which could pump the motion up, estimate after estimate): v is
    /// scaled down instead, as a damping event would.
    ///
    /// \param[in] q The configuration (dim model.nq).
    /// \param[in,out] v The joint velocity (dim model.nv).
    /// \param[in] step The step index, to space the next estimate.
    /// \return The kinetic energy the change of the added inertia took out of the run (J): the
    ///         share of the inertia taken away; 0 where inertia was added (v is scaled to keep
    ///         the energy the same).
    ///
    double estimate(
      pinocchio::Data & data, const Eigen::VectorXd & q, Eigen::VectorXd & v, std::int64_t step);

    /// \brief Whether an automatic step is due for a new estimate: a window since the last one
    /// and a move of more than kFarMove.
    bool isEstimateDue(const Eigen::VectorXd & q, std::int64_t step);

    ///
    /// \brief Halve the step for the rest of the run (after a roll-back to q, v); the
    /// automatic step is re-estimated there, and kept no longer than the halved one.
    /// \return As estimate (0 with a fixed step).
    ///
    double halve(
      pinocchio::Data & data, const Eigen::VectorXd & q, Eigen::VectorXd & v, std::int64_t step);

    /// \brief The current estimate (its stiff modes' added inertia).
    const TimeScale & timeScale() const
    {
      return time_scale_;
    }

    /// \brief Number of scaled stiff modes of the current estimate.
    Eigen::Index stiffModes() const
    {
      return time_scale_.stiff_masses.size();
    }

    /// \brief Kinetic energy of the scaled modes' and joints' added inertia at the velocity v
    /// (J); 0 when none are scaled.
    double addedEnergy(const Eigen::VectorXd & v);

    /// \brief The model whose dynamics the run follows: the model, or its copy with the
    /// joints' added inertia in its armature.
    const pinocchio::Model & dynamicsModel() const
    {
      return inertia_active_ ? scaled_model_ : model_;
    }

    /// \brief Most joints given an added inertia by one estimate.
    int scaledJoints() const
    {
      return scaled_joints_;
    }

    /// \brief Changes whenever dynamicsModel()'s armature may have (each run, each estimate),
    /// never back to an earlier value.
    std::uint64_t dynamicsVersion() const
    {
      return dynamics_version_;
    }

    ///
    /// \brief The acceleration in data.ddq under M + W^T diag(d) W instead of M (the stiff
    /// modes' added inertia), by the Woodbury identity: a' = a - Y (diag(d)^-1 + W Y)^-1 W a,
    /// Y = M^-1 W^T. Nothing happens when no mode is scaled.
    ///
    /// \param[in,out] data Holds pinocchio::aba on dynamicsModel() in the world convention at
    ///            the step's configuration (the step's dynamics: its articulated inertias give
    ///            M^-1), with data.ddq the acceleration to correct.
    ///
    void correctAcceleration(pinocchio::Data & data);

    ///
    /// \brief The length of the next step (s): dt, with the automatic step grown since the last
    /// restartGrowth and shortened so that no joint moves more than dt_safety (rad or m) in it. The
    /// step moves q by h (v + h a): the velocity after the kick counts, since a step estimated
    /// where the mechanism is soft (on a hump, K < 0) may take it in one stride into a stiff region
    /// and across the next hump.
    ///
    /// \param[in] v The velocity before the step (dim model.nv).
    /// \param[in] a The acceleration of the step (dim model.nv).
    ///
    double nextStep(const Eigen::VectorXd & v, const Eigen::VectorXd & a);

    /// \brief Start the automatic step's growth again from the estimate: after a damping
    /// event, a push or a roll-back the motion starts anew, and its fast modes with it.
    void restartGrowth()
    {
      growth_ = 1.;
    }

    /// \brief The length of the step taken last (s).
    double lastStep() const
    {
      return h_;
    }

    /// \brief The step in force (s), the estimates made, the most modes scaled by one.
    double dt() const
    {
      return dt_;
    }
    int estimates() const
    {
      return estimates_;
    }
    int scaledModes() const
    {
      return scaled_modes_;
    }

  private:
    double kineticEnergyOfAdded(const TimeScale & scale, const Eigen::VectorXd & v) const;
    /// The time scale at q, with the joints' added inertia re-chosen there when they scale.
    TimeScale estimateTimeScale(pinocchio::Data & data, const Eigen::VectorXd & q);

    const pinocchio::Model & model_;
    const LoopConstraints * loops_;
    bool stiff_modes_allowed_;
    const ForceModel * forces_ = nullptr;
    bool automatic_ = false, scale_stiff_modes_ = false;
    double dt_safety_ = 0., dt_ = 0., h_ = 0., step_scale_ = 1.;
    // The factor on dt_ of the next automatic step, and its largest value.
    double growth_ = 1., max_growth_ = 1.;
    std::int64_t estimated_at_ = 0, estimate_spacing_ = 1;
    int estimates_ = 0, scaled_modes_ = 0, scaled_joints_ = 0;
    // The joints' added inertia (Settings::scale_joint_inertia) and the model that carries it.
    bool scale_joint_inertia_ = false, inertia_active_ = false, scaled_model_current_ = false;
    std::uint64_t dynamics_version_ = 0;
    Eigen::VectorXd joint_inertia_;
    pinocchio::Model scaled_model_;
    // The last estimate (its stiff-mode scaling applies to every step) and where it was made.
    TimeScale time_scale_;
    Eigen::VectorXd q_estimate_, moved_, a_;
    // Workspace of the stiff-mode correction, sized at each estimate.
    Eigen::MatrixXd stiff_y_, stiff_s_;
    Eigen::VectorXd stiff_z_, stiff_p_;
    Eigen::LLT<Eigen::MatrixXd> stiff_llt_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_step_control_hpp__
