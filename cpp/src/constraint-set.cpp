//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/constraint-set.hpp"
#include "pinsettle/solver.hpp"
#include "pinsettle/statics.hpp"
#include "pinsettle/step-control.hpp"
#include "joint-kinds.hpp"
#include "loop-stepper.hpp"

#include "pinsettle/prebuilt.hpp"

#include <algorithm>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace pinsettle
{

  ConstraintSet::ConstraintSet(
    const pinocchio::Model & model,
    const LoopConstraints * loops,
    const JointStops * stops,
    const GroundContacts * contacts)
  : model_(model)
  , loops_(loops != nullptr && !loops->empty() ? loops : nullptr)
  , stops_(stops != nullptr && !stops->empty() ? stops : nullptr)
  , contacts_(contacts != nullptr && !contacts->empty() ? contacts : nullptr)
  {
    if (contacts_ != nullptr)
    {
      if (&contacts_->model() != &model)
        throw std::invalid_argument("contacts: they were made for another model than the solver's");
      if (loops_ != nullptr)
        throw std::invalid_argument(
          "contacts: ground contacts together with loops or joint couplings are not supported "
          "yet; remove the loops or the contacts");
      contact_stepper_.reset(new ContactStepper(*contacts_, stops_));
    }
    if (loops_ != nullptr)
    {
      if (&loops_->model() != &model)
        throw std::invalid_argument("loops: they were made for another model than the solver's");
      stepper_.reset(new LoopStepper(model, *loops_));
    }
    if (stops_ != nullptr)
    {
      if (&stops_->model() != &model)
        throw std::invalid_argument("stops: they were made for another model than the solver's");
      // With contacts the stops are rows of the contacts' impulse solve, not held apart.
      if (contacts_ == nullptr)
        hold_.reset(new StopHold(*stops_, loops_));
      if (stepper_)
        stepper_->useStops(stops_);
      hits_.reserve(stops_->stops().size());
      on_stops_.reserve(stops_->stops().size());
    }
  }

  ConstraintSet::~ConstraintSet() = default;

  void ConstraintSet::start(
    pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, Info & info)
  {
    info.mobility = model_.nv;
    if (contact_stepper_)
      contact_stepper_->start();
    if (loops_ != nullptr)
      assemble(data, q, v, info);
    if (stops_ == nullptr)
      return;
    if (hold_)
      hold_->start();
    clampToStops(*stops_, q, &info.start_clamped);
    pinsettle::enforceStops(*stops_, q, v);
    if (loops_ != nullptr && !info.start_clamped.empty())
      closeLoopsOnStops(data, q, v);
  }

  void ConstraintSet::assemble(
    pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, Info & info)
  {
    // Closed mechanism: start assembled, with a velocity the loops allow.
    info.assembly_distance = assembleLoops(model_, data, *loops_, q);
    const LoopMotion motion = computeLoopMotion(model_, data, *loops_, q);
    info.mobility = static_cast<int>(motion.basis.cols());
    if (info.mobility == 0)
    {
      std::ostringstream msg;
      msg << "the loops leave the mechanism no degree of freedom (" << motion.rank
          << " independent loop equations on model.nv = " << model_.nv
          << " joint velocities): it is a structure, with nothing to settle";
      throw std::invalid_argument(msg.str());
    }
    v = motion.basis * (motion.basis.transpose() * v);
    stepper_->init(data, q);
  }

  void ConstraintSet::closeLoopsOnStops(
    pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v)
  {
    findJointsOnStops(*stops_, q, on_stops_);
    const double left = projectOntoLoops(model_, data, *loops_, q, 1e-13, 100, &on_stops_);
    if (!(left <= LoopStepper::kLoopTolerance))
    {
      std::ostringstream msg;
      msg << "cannot close the loops with the joints moved onto their stops held there (";
      for (std::size_t k = 0; k < on_stops_.size(); ++k)
        msg << (k > 0 ? ", " : "") << describeCoordinate(model_, on_stops_[k]);
      msg << "): they stay " << left
          << " (m or rad) open; give a start inside the limits from which the loops close";
      throw std::invalid_argument(msg.str());
    }
    stepper_->project(data, q, v, &on_stops_); // and a velocity they allow
  }

  Eigen::VectorXd ConstraintSet::computeStaticForce(
    pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const
  {
    if (loops_ != nullptr)
      return pinsettle::computeStaticForce(model_, data, *loops_, q, forces);
    return pinsettle::computeStaticForce(model_, data, q, forces);
  }

  std::string ConstraintSet::explainFreeFall(
    pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const
  {
    if (contacts_ != nullptr)
      return std::string();
    return pinsettle::explainFreeFall(model_, data, q, forces, loops_, stops_);
  }

  double ConstraintSet::computeResidual(
    pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & tau) const
  {
    if (contacts_ != nullptr)
      return balanceContacts(model_, data, *contacts_, q, tau, stops_).residual;
    if (stops_ != nullptr && loops_ != nullptr)
      return balanceStops(model_, data, *loops_, *stops_, q, tau).residual;
    if (stops_ != nullptr)
      return computeStopResidual(*stops_, q, tau);
    return tau.lpNorm<Eigen::Infinity>();
  }

  StabilityReport ConstraintSet::assessStability(
    pinocchio::Data & data, const Eigen::VectorXd & q, const ForceModel * forces) const
  {
    if (contacts_ != nullptr)
      return pinsettle::assessStability(model_, data, *contacts_, q, forces, stops_);
    if (loops_ != nullptr && stops_ != nullptr)
      return pinsettle::assessStability(model_, data, *loops_, *stops_, q, forces);
    if (loops_ != nullptr)
      return pinsettle::assessStability(model_, data, *loops_, q, forces);
    if (stops_ != nullptr)
      return pinsettle::assessStability(model_, data, *stops_, q, forces);
    return pinsettle::assessStability(model_, data, q, forces);
  }

  bool ConstraintSet::isSatisfied(pinocchio::Data & data, const Eigen::VectorXd & q) const
  {
    if (contacts_ != nullptr && !isClearOfGrounds(model_, data, *contacts_, q))
      return false;
    return loops_ == nullptr
           || computeLoopError(model_, data, *loops_, q).lpNorm<Eigen::Infinity>()
                <= LoopStepper::kLoopTolerance;
  }

  void ConstraintSet::describeRest(
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau,
    Result & result) const
  {
    if (loops_ != nullptr)
      result.constraint_error =
        computeLoopError(model_, data, *loops_, q).lpNorm<Eigen::Infinity>();
    if (contacts_ != nullptr)
    {
      ContactBalance balance = balanceContacts(model_, data, *contacts_, q, tau, stops_);
      double mass = 0.; // kg
      for (const pinocchio::Inertia & body : model_.inertias)
        mass += body.mass();
      const double weight = mass * model_.gravity.linear().norm();
      result.ground_contacts = describeContacts(*contacts_, balance, weight);
      const auto byAThread = [](const GroundContact & c) { return c.marginal; };
      if (
        result.stability == Stability::Stable
        && std::any_of(result.ground_contacts.begin(), result.ground_contacts.end(), byAThread))
        result.stability = Stability::Marginal;
      result.stop_contacts = std::move(balance.stops);
    }
    else if (stops_ != nullptr && loops_ != nullptr)
      result.stop_contacts = balanceStops(model_, data, *loops_, *stops_, q, tau).contacts;
    else if (stops_ != nullptr)
      result.stop_contacts = computeStopContacts(*stops_, q, tau);
  }

  bool ConstraintSet::projectConfiguration(pinocchio::Data & data, Eigen::VectorXd & q)
  {
    double open = 0.; // the loops' error left at q
    if (loops_ != nullptr)
      open = projectOntoLoops(model_, data, *loops_, q);
    if (stops_ != nullptr)
      clampToStops(*stops_, q);
    if (loops_ != nullptr && stops_ != nullptr)
    {
      findJointsOnStops(*stops_, q, on_stops_);
      open = projectOntoLoops(model_, data, *loops_, q, 1e-13, 50, &on_stops_);
    }
    return open <= LoopStepper::kLoopTolerance
           && (contacts_ == nullptr || isClearOfGrounds(model_, data, *contacts_, q));
  }

  const pinocchio::Model * ConstraintSet::lockedModel(
    const StepController & step_control, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    // Joints held on their stops at the last step stay locked while they rest: one ABA.
    if (hold_ == nullptr)
      return nullptr;
    hold_->useDynamicsModel(step_control.dynamicsModel(), step_control.dynamicsVersion());
    return hold_->lockedModel(q, v, &step_control.timeScale());
  }

  void ConstraintSet::computeAcceleration(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    const Eigen::VectorXd & tau,
    const ForceVector * fext)
  {
    dynamics_model_ = &model;
    if (loops_ != nullptr)
      stepper_->dynamics(data, q, v, tau, fext);
    else if (fext != nullptr)
      prebuilt::aba(model, data, q, v, tau, *fext, dynamicsConvention());
    else
      prebuilt::aba(model, data, q, v, tau, dynamicsConvention());
  }

  bool ConstraintSet::acceptLocked(
    pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    return hold_->acceptLocked(data, q, v);
  }

  const pinocchio::Model * ConstraintSet::unlockPulled(
    const pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    return hold_->unlockPulled(data, q, v);
  }

  void ConstraintSet::hold(
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    const TimeScale & added)
  {
    if (hold_ != nullptr)
      hold_->hold(data, q, v, &added);
  }

  void ConstraintSet::resolveContacts(
    pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v, double h)
  {
    if (contact_stepper_ != nullptr)
      contact_stepper_->apply(
        dynamics_model_ != nullptr ? *dynamics_model_ : model_, data, q, v, data.ddq, h);
  }

  bool ConstraintSet::enforceStops(
    Eigen::VectorXd & q, Eigen::VectorXd & v, bool record, Eigen::VectorXd & motion)
  {
    if (stops_ == nullptr)
      return false;
    hits_.clear();
    if (loops_ != nullptr) // the impact in the loops starts from the arriving velocity
      stepper_->arrive(v);
    if (contact_stepper_ == nullptr)
      return pinsettle::enforceStops(*stops_, q, v, record ? &hits_ : nullptr, 0., &motion);
    // Stops solved with the contacts' impulses are landed on, to the solve's accuracy: a joint
    // resting on one, a round-off past it at every step, is no chatter (talos with its motors
    // off, knees folded on their stops, was rolled back every ten steps down to a step of
    // 5e-5 s). A joint that comes onto one from off it hits it.
    const bool past = pinsettle::enforceStops(
      *stops_, q, v, record ? &hits_ : nullptr, kContactGapTolerance, &motion);
    return contact_stepper_->addStopsReached(q, record ? &hits_ : nullptr) || past;
  }

  void ConstraintSet::projectStep(
    pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v, bool hit)
  {
    if (loops_ == nullptr)
      return;
    if (stops_ == nullptr)
    {
      stepper_->project(data, q, v);
      return;
    }
    // Back onto the loops with the joints on a stop kept there. Zeroing a joint's speed and
    // projecting in joint coordinates handed the impact's energy to the rest of the loop:
    // Fetch's weld-hung arm rang at its stops for ever.
    findJointsOnStops(*stops_, q, on_stops_);
    if (hit)
      stepper_->impact(data, q, v, on_stops_);
    else
      stepper_->project(data, q, v, &on_stops_);
  }

  void ConstraintSet::projectState(pinocchio::Data & data, Eigen::VectorXd & q, Eigen::VectorXd & v)
  {
    if (loops_ != nullptr)
      stepper_->project(data, q, v);
  }

} // namespace pinsettle
