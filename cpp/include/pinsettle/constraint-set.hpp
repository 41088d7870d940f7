//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_constraint_set_hpp__
#define __pinsettle_constraint_set_hpp__

#include "pinsettle/contacts.hpp"
#include "pinsettle/forces.hpp"
#include "pinsettle/loops.hpp"
#include "pinsettle/result.hpp"
#include "pinsettle/stability.hpp"
#include "pinsettle/stops.hpp"

#include <memory>
#include <vector>

namespace pinsettle
{

  class LoopStepper;
  class StepController;

  ///
  /// \brief Everything that restricts the mechanism's motion, as one object: the loop closures
  /// (LoopConstraints), the joint stops (JointStops) and the ground contacts (GroundContacts)
  /// of a scene, any of them or none.
  ///
  /// The solver's step loop and its Newton iterations ask this set for what a rest and a step
  /// need (the static force and residual of a rest, its stability report, the dynamics of a
  /// step, the impacts and projections after it) and never which kinds of constraint are
  /// present; how the kinds combine (a loop with a joint held on its stop) is decided here.
  /// Without constraints every operation is the bare mechanism's (pinocchio::aba, the static
  /// force, its stiffness), at the bare mechanism's cost.
  ///
  /// Built once per solver; holds the workspace of the loops' dynamics and the stops' hold.
  /// The model, the loops and the stops must outlive it.
  ///
  class ConstraintSet
  {
  public:
    ///
    /// \param[in] loops Loop closures (empty or nullptr: none).
    /// \param[in] stops Joint stops (empty or nullptr: none).
    /// \param[in] contacts Ground contacts (empty or nullptr: none).
    /// \throws std::invalid_argument when loops, stops or contacts were made for another model,
    ///         or for contacts with loops (not supported yet).
    ///
    ConstraintSet(
      const pinocchio::Model & model,
      const LoopConstraints * loops,
      const JointStops * stops,
      const GroundContacts * contacts = nullptr);
    ~ConstraintSet();

    /// Whether nothing restricts the motion (every joint velocity free).
    bool empty() const
    {
      return loops_ == nullptr && stops_ == nullptr && contacts_ == nullptr;
    }
    /// The loop closures, or nullptr.
    const LoopConstraints * loops() const
    {
      return loops_;
    }
    /// The joint stops, or nullptr.
    const JointStops * stops() const
    {
      return stops_;
    }
    /// The ground contacts, or nullptr.
    const GroundContacts * contacts() const
    {
      return contacts_;
    }

    ///
    /// \brief Why the mechanism at q falls for ever with nothing to stop it (explainFreeFall),
    /// or empty. A mechanism with ground contacts may fall onto the ground: never said.
    ///
    std::string explainFreeFall(
      pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const;

    /// Whether the step may slow stiff modes (StepController): not with ground contacts, whose
    /// impulses are solved in the mechanism's own mass matrix.
    bool allowsStiffModeScaling() const
    {
      return contacts_ == nullptr;
    }

    // --- The start of a run -------------------------------------------------------------------

    ///
    /// \brief Move the start onto the constraints: the loops assembled (Info::assembly_distance)
    /// with a velocity they allow, q moved into the stops' ranges (Info::start_clamped) and the
    /// velocity into a stop removed, the loops closed again with the clamped joints held.
    ///
    /// \param[in,out] q The start configuration (dim model.nq).
    /// \param[in,out] v The start velocity (dim model.nv).
    /// \param[out] info Its mobility, assembly_distance and start_clamped are set.
    /// \throws std::invalid_argument when the loops leave no degree of freedom or cannot be
    ///         closed with the clamped joints held.
    ///
    void start(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, Info & info);

    // --- A rest -------------------------------------------------------------------------------

    ///
    /// \brief Net static generalized force of the constrained mechanism at q (dim model.nv,
    /// N m or N): with loops the one projected onto the motions they allow
    /// (pinsettle::computeStaticForce).
    ///
    Eigen::VectorXd computeStaticForce(
      pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const;

    ///
    /// \brief Residual of a rest at q with static force tau (N m or N): the largest violation of
    /// its conditions (zero force on free motions, stops pressed into, not pulled).
    ///
    double computeResidual(
      pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & tau) const;

    ///
    /// \brief Stability of a rest at q: the stiffness restricted to the motions the constraints
    /// leave free; the report's basis spans them (empty without constraints: every motion).
    ///
    StabilityReport assessStability(
      pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const;

    ///
    /// \brief Whether q satisfies the constraints a rest must (the loops closed to
    /// LoopStepper::kLoopTolerance, no contact sunk into a ground beyond
    /// kContactGapTolerance): a pose that does not is no rest.
    ///
    bool isSatisfied(pinocchio::Data & data, const Eigen::VectorXd & q) const;

    ///
    /// \brief The constraints' part of the answer at q with static force tau: the loops' error
    /// (result.constraint_error), the stops' contacts and reactions (result.stop_contacts) and
    /// the ground contacts with their forces (result.ground_contacts); a stable rest held by a
    /// marginal contact becomes Stability::Marginal (result.stability is set before).
    ///
    void describeRest(
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & tau,
      Result & result) const;

    ///
    /// \brief Move a configuration a Newton step reached back onto the constraints: onto the
    /// loops, into the stops' ranges, onto the loops again with the joints on a stop held.
    ///
    /// \param[in,out] q The configuration (dim model.nq).
    /// \return Whether the loops close there (isSatisfied's tolerance) and no contact sinks
    ///         into a ground; a pose the stops hold open, or sunk in, is no step to a rest.
    ///
    bool projectConfiguration(pinocchio::Data & data, Eigen::VectorXd & q);

    // --- A step -------------------------------------------------------------------------------

    /// The convention the step's dynamics leave the body velocities in (data.v or data.ov).
    pinocchio::Convention dynamicsConvention() const
    {
      // ABA in the world convention is the faster (6 to 8 % on 6 to 9 joint arms); the loops'
      // dynamics leave the body velocities in local frames.
      return loops_ != nullptr ? pinocchio::Convention::LOCAL : pinocchio::Convention::WORLD;
    }

    ///
    /// \brief The model to run this step's dynamics on: with joints resting on their stops the
    /// one with them locked (StopHold::lockedModel), else nullptr (step_control's).
    ///
    const pinocchio::Model * lockedModel(
      const StepController & step_control, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    ///
    /// \brief The acceleration of the step (data.ddq, dim model.nv) on model: pinocchio::aba, or
    /// with loops their constrained dynamics.
    ///
    /// \param[in] tau Applied joint efforts (dim model.nv, N m or N).
    /// \param[in] fext One spatial force per joint (local frames), or nullptr.
    ///
    void computeAcceleration(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const Eigen::VectorXd & tau,
      const ForceVector * fext);

    /// After the dynamics of lockedModel(): StopHold::acceptLocked.
    bool acceptLocked(pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);
    /// After acceptLocked() said no: StopHold::unlockPulled.
    const pinocchio::Model * unlockPulled(
      const pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    ///
    /// \brief Replace the free acceleration data.ddq by the one with the joints resting on their
    /// stops held (StopHold::hold); nothing without stops.
    ///
    void hold(
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const TimeScale & added);

    ///
    /// \brief Before the step of length h is integrated: the ground contacts' impulses folded
    /// into the acceleration data.ddq (ContactStepper), on the model the dynamics ran on.
    /// Nothing without contacts.
    ///
    void resolveContacts(
      pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v, double h);

    ///
    /// \brief After a step: a joint past a stop put on it with its velocity into the stop
    /// removed (an inelastic impact; enforceStops).
    ///
    /// \param[in] record Whether to list the joints that hit a stop (hits()).
    /// \param[in,out] motion The step's motion in tangent coordinates (dim model.nv), corrected
    ///            by the moves onto the stops (a joint held on a stop makes no net motion).
    /// \return Whether a joint was past a stop.
    ///
    bool enforceStops(
      Eigen::VectorXd & q, Eigen::VectorXd & v, bool record, Eigen::VectorXd & motion);
    /// The joints that hit a stop in the last enforceStops(record = true).
    const std::vector<pinocchio::JointIndex> & hits() const
    {
      return hits_;
    }

    ///
    /// \brief After a step and enforceStops(): q back onto the loops and v onto the motions they
    /// allow, the joints on a stop kept there; after an impact (hit) the velocity nearest to the
    /// arriving one in the mass metric (LoopStepper::impact). Nothing without loops.
    ///
    void projectStep(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, bool hit);

    ///
    /// \brief A state moved back along the path (a backtrack to a peak) put back onto the loops
    /// with a velocity they allow. Nothing without loops.
    ///
    void projectState(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v);

  private:
    // Info::mobility, assembly_distance: the loops assembled, v onto their motions.
    void assemble(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, Info & info);
    // The loops closed with the joints moved onto their stops at the start held there.
    void closeLoopsOnStops(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v);

    const pinocchio::Model & model_;
    const LoopConstraints * loops_;
    const JointStops * stops_;
    const GroundContacts * contacts_;
    const pinocchio::Model * dynamics_model_ = nullptr; // of the last computeAcceleration
    std::unique_ptr<LoopStepper> stepper_;
    std::unique_ptr<ContactStepper> contact_stepper_;
    std::unique_ptr<StopHold> hold_;
    std::vector<pinocchio::JointIndex> hits_; // joints that hit a stop in a step
    std::vector<Eigen::Index> on_stops_;      // indices in v of joints on a stop
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_constraint_set_hpp__
