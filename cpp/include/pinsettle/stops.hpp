//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_stops_hpp__
#define __pinsettle_stops_hpp__

#include "pinsettle/stability.hpp"

#include <Eigen/Cholesky>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace pinsettle
{
  class LoopConstraints;

  /// \brief Which side of its range a joint rests against.
  enum class StopSide
  {
    Lower,
    Upper
  };

  /// \brief "lower" or "upper".
  const char * toString(StopSide side);

  /// \brief A joint resting on one of its stops, and the stop's reaction.
  struct StopContact
  {
    pinocchio::JointIndex joint;
    StopSide side;
    /// Force the stop exerts, >= 0, pushing the joint away from it (N m or N).
    double reaction;
  };

  ///
  /// \brief Position stops of a model's 1-DoF joints (revolute, prismatic, helical): unilateral
  /// and inelastic, a joint pushed into a stop stays on it.
  ///
  /// By default they are the model's position limits (model.lowerPositionLimit,
  /// model.upperPositionLimit; a URDF's <limit lower upper>), with three exceptions that are no
  /// stop: a joint whose lower and upper limits are equal (the URDF default when they are left
  /// out; equalLimitJoints lists them), a bound that is not finite or beyond kNoLimit (a model
  /// built in code), and joints with more than one configuration entry (continuous, spherical,
  /// free-flyer, planar; unappliedLimitJoints lists those with limits of their own). setLimit
  /// adds or overrides a stop.
  ///
  class JointStops
  {
  public:
    /// Bounds this large (rad or m) or larger are no stop.
    static constexpr double kNoLimit = 1e10;

    /// \brief A stop of one joint; either bound may be infinite (no stop on that side).
    struct Stop
    {
      pinocchio::JointIndex joint;
      int iq; ///< index in q
      int iv; ///< index in v
      double lower, upper;
    };

    ///
    /// \param[in] model The mechanism (it must outlive the stops).
    /// \param[in] from_model Take the model's position limits; false: start with none.
    ///
    explicit JointStops(const pinocchio::Model & model, bool from_model = true);

    ///
    /// \brief Add or override the stops of a joint.
    ///
    /// \param[in] lower Lower stop (rad or m), -infinity for none.
    /// \param[in] upper Upper stop (rad or m), +infinity for none.
    /// \throws std::invalid_argument for a joint that is not 1-DoF with one configuration entry
    ///         (named), a NaN, or lower > upper.
    ///
    void setLimit(pinocchio::JointIndex joint, double lower, double upper);

    /// \brief Remove the stops of a joint (nothing happens when it has none).
    void removeLimit(pinocchio::JointIndex joint);

    /// \brief Whether there is no stop at all; the solver then runs nothing of them.
    bool empty() const
    {
      return stops_.empty();
    }

    const std::vector<Stop> & stops() const
    {
      return stops_;
    }

    /// \brief Joints whose model limits were equal and were taken as no stop.
    const std::vector<pinocchio::JointIndex> & equalLimitJoints() const
    {
      return equal_limits_;
    }

    /// \brief Joints of several configuration entries (planar, spherical, free-flyer,
    /// continuous) whose model limits are not Pinocchio's placeholders: no stop applies them.
    /// The placeholders are bounds beyond kNoLimit and, on entries of unit norm (a quaternion,
    /// a continuous joint's cos and sin), bounds of magnitude 1 or more.
    const std::vector<pinocchio::JointIndex> & unappliedLimitJoints() const
    {
      return unapplied_limits_;
    }

    const pinocchio::Model & model() const
    {
      return model_;
    }

  private:
    const pinocchio::Model & model_;
    std::vector<Stop> stops_;
    std::vector<pinocchio::JointIndex> equal_limits_;
    std::vector<pinocchio::JointIndex> unapplied_limits_;
  };

  ///
  /// \brief Move q into the stops' ranges.
  ///
  /// \param[in,out] q The configuration (dim model.nq).
  /// \param[out] moved Each joint moved and by how much (rad or m), or nullptr.
  /// \return The largest move (rad or m); 0 when q was inside.
  ///
  double clampToStops(
    const JointStops & stops,
    Eigen::VectorXd & q,
    std::vector<std::pair<pinocchio::JointIndex, double>> * moved = nullptr);

  ///
  /// \brief The inelastic impact: a joint past a stop is put on it and its velocity into the
  /// stop removed (also the velocity into a stop it rests on).
  ///
  /// \param[in,out] q The configuration (dim model.nq).
  /// \param[in,out] v The joint velocity (dim model.nv).
  /// \param[out] hits When given, the joints that were past a stop are appended to it.
  /// \param[in] slack How near a stop (rad or m), on either side, a joint lands on it: it is
  ///            put on it, and counts as having hit it only from further past.
  /// \param[in,out] motion When given, the step's motion in tangent coordinates (dim
  ///            model.nv), corrected by the moves onto the stops.
  /// \return Whether a joint was past a stop by more than the slack.
  ///
  bool enforceStops(
    const JointStops & stops,
    Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    std::vector<pinocchio::JointIndex> * hits = nullptr,
    double slack = 0.,
    Eigen::VectorXd * motion = nullptr);

  ///
  /// \brief The joints exactly on a stop at q.
  ///
  /// \param[out] iv Their indices in v (cleared first).
  ///
  void findJointsOnStops(
    const JointStops & stops, const Eigen::VectorXd & q, std::vector<Eigen::Index> & iv);

  ///
  /// \brief The joints resting on a stop at q and the stops' reactions, from the static force.
  ///
  /// A joint exactly on a stop is listed with reaction max(0, tau) at a lower stop and
  /// max(0, -tau) at an upper one (0 when the static force pulls it off the stop).
  ///
  /// \param[in] q The configuration (dim model.nq).
  /// \param[in] tau The net static generalized force at q (dim model.nv, computeStaticForce).
  ///
  std::vector<StopContact> computeStopContacts(
    const JointStops & stops, const Eigen::VectorXd & q, const Eigen::VectorXd & tau);

  /// \brief A joint on one of its stops: the stop and the side.
  struct StopReached
  {
    const JointStops::Stop * stop;
    StopSide side;
    /// +1 on a lower stop, -1 on an upper one: the direction the stop pushes the joint.
    double sign() const
    {
      return side == StopSide::Lower ? 1. : -1.;
    }
  };

  /// \brief The joints on a stop at q (q[iq] at or past a bound, or within slack of it: rad or
  /// m), in the stops' order.
  std::vector<StopReached> findStopsReached(
    const JointStops & stops, const Eigen::VectorXd & q, double slack = 0.);

  ///
  /// \brief The residual of a rest against stops: the largest violation of its conditions.
  ///
  /// Off the stops the static force must vanish (|tau|); on a lower stop it must press into the
  /// stop (tau >= 0, violation max(0, -tau)); on an upper stop likewise (max(0, tau)).
  ///
  /// \return The residual (N m or N).
  ///
  double computeStopResidual(
    const JointStops & stops, const Eigen::VectorXd & q, const Eigen::VectorXd & tau);

  ///
  /// \brief The tangent directions free at q: every joint velocity but those of joints resting
  /// on a stop with a reaction above tolerance.
  ///
  /// \return The selection matrix B (dim model.nv x number of free directions): K restricted to
  ///         them is B^T K B.
  ///
  Eigen::MatrixXd computeFreeDirections(
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau,
    double tolerance);

  ///
  /// \brief Stability of a rest against stops: the stiffness restricted to the free directions
  /// (computeFreeDirections, a stop whose reaction is within 1e-9 of the largest static force
  /// counted as free). The report's basis is that selection; stiffness is B^T K B.
  ///
  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Holding joints on their stops during a step: the part of the solver's loop that
  /// turns the free acceleration into the one with the resting joints held.
  ///
  /// A joint resting on a stop (exactly on it, not moving off it) is held when its
  /// acceleration points into the stop. The held acceleration solves M a = f with a = 0 on the
  /// held joints, f = M a_free the generalized force of the free motion; a held joint whose
  /// stop would have to pull is released and a resting joint that the others now accelerate
  /// into its stop is held, until neither happens (an active set). Nothing is computed when no
  /// resting joint is accelerated into its stop.
  ///
  class StopHold
  {
  public:
    ///
    /// \param[in] loops Loop closures of the mechanism, or nullptr: with loops the held motion is
    ///            the one of the closed mechanism (a = a_free + N y, N the motions the loops
    ///            allow, y of least kinetic metric N^T M N, with the held joints' a at zero).
    ///
    explicit StopHold(const JointStops & stops, const LoopConstraints * loops = nullptr);

    ///
    /// \brief Forget what a previous run left: no joint locked, no diagonal mass known, the
    /// model's own dynamics followed. A run starts here, as on a new StopHold.
    ///
    void start();

    ///
    /// \brief Replace the free acceleration data.ddq by the held one.
    ///
    /// \param[in] q, v The state (on the stops' ranges, as enforceStops leaves it).
    /// \param[in] added Extra inertia W^T diag(d) W of scaled stiff modes (TimeScale), or
    ///            nullptr; the held motion is that of the same scaled system.
    /// \return Whether a joint is held.
    ///
    bool hold(
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const TimeScale * added);

    ///
    /// \brief The model to run the next step's dynamics on while joints rest on their stops:
    /// the mechanism with every resting joint locked, or nullptr.
    ///
    /// A locked joint has an armature of kLockArmature times its diagonal mass (as last
    /// computed by hold()), so that pinocchio::aba passes its subtree's inertia on to its
    /// parent all but unprojected, as if the joint were welded, and its acceleration is about
    /// 1e-12 of the free one's scale: one ABA gives the held motion that hold() finds with the
    /// free ABA, a mass matrix and an active set, whenever every resting joint is held.
    /// nullptr when no joint rests (on a stop with v = 0), one has no diagonal mass yet, loops
    /// close the mechanism or stiff modes are scaled (their correction assumes the free model).
    ///
    const pinocchio::Model * lockedModel(
      const Eigen::VectorXd & q, const Eigen::VectorXd & v, const TimeScale * added);

    ///
    /// \brief After the dynamics of lockedModel(): whether every locked joint is pressed into
    /// its stop and no other resting joint is accelerated into its own; if so, the locked
    /// joints' accelerations are set to zero in data.ddq.
    ///
    bool acceptLocked(pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    ///
    /// \brief After acceptLocked() said no: the model with the locked joints that are pulled off
    /// their stop unlocked, to run the dynamics on once more, or nullptr when that cannot be the
    /// answer (a resting joint not locked is accelerated into its stop, or none was pulled
    /// off): then the free dynamics and hold() decide.
    ///
    const pinocchio::Model * unlockPulled(
      const pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    ///
    /// \brief Run the held and locked dynamics on model: the stops' model with the joints'
    /// added inertia in its armature (StepController::dynamicsModel), which must outlive this.
    /// \param[in] version Changes whenever that armature may have (the locked model is then
    ///            built again), never back to an earlier value
    ///            (StepController::dynamicsVersion).
    ///
    void useDynamicsModel(const pinocchio::Model & model, std::uint64_t version);

    /// Armature of a locked joint over its diagonal mass.
    static constexpr double kLockArmature = 1e12;

  private:
    // Joints resting on a stop at (q, v): (index in v, +1 lower stop / -1 upper stop).
    void findResting(const Eigen::VectorXd & q, const Eigen::VectorXd & v);
    // Lock the joints of stops whose side_ is not 0 in locked_ (from the model's armature).
    void lock();
    // Whether the joint of stop k rests on it (+1 lower, -1 upper, 0 not), moving or not.
    static double restingSide(const JointStops::Stop & s, const Eigen::VectorXd & q, double v);

    // The acceleration with the held joints' at zero, M_ff a_f = f_f, and the stops' forces
    // (reactions_, one per resting joint, 0 for those not held).
    void solveHeld(const std::vector<bool> & held, Eigen::VectorXd & a);
    // The same for the closed mechanism, on the motions the loops allow (motions_).
    void solveHeldOnLoops(
      const std::vector<bool> & held, const Eigen::VectorXd & a_free, Eigen::VectorXd & a);

    const JointStops & stops_;
    const LoopConstraints * loops_;
    Eigen::MatrixXd motions_;
    Eigen::VectorXd reactions_;
    // Joints resting on a stop: (index in v, +1 lower stop / -1 upper stop).
    std::vector<std::pair<int, double>> resting_;
    std::vector<int> free_;
    Eigen::MatrixXd mass_, mass_ff_;
    Eigen::VectorXd force_, force_f_, free_acceleration_, held_acceleration_;
    Eigen::LLT<Eigen::MatrixXd> llt_;
    std::vector<bool> held_, fixed_;
    // The model with resting joints locked; per stop, the side its joint is locked on (0: not
    // locked), the side wanted for the next lock and its diagonal mass when last computed (0:
    // not yet).
    pinocchio::Model locked_;
    std::vector<double> locked_side_, side_, lock_mass_;
    // The model whose dynamics the run follows, and the version of its armature.
    const pinocchio::Model * dynamics_;
    std::uint64_t dynamics_version_ = 0;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_stops_hpp__
