//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/solver.hpp"
#include "pinsettle/energy.hpp"
#include "pinsettle/model-checks.hpp"
#include "pinsettle/stability.hpp"
#include "joint-kinds.hpp"
#include "unit-norm.hpp"

#include "pinsettle/prebuilt.hpp"
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pinsettle
{

  void checkConfiguration(
    const pinocchio::Model & model, const Eigen::VectorXd & q, const char * name)
  {
    if (q.size() != model.nq)
    {
      std::ostringstream msg;
      msg << name << " must have model.nq = " << model.nq << " entries, got " << q.size();
      throw std::invalid_argument(msg.str());
    }
    for (Eigen::Index k = 0; k < q.size(); ++k)
    {
      if (!std::isfinite(q[k]))
      {
        std::ostringstream msg;
        msg << name << "[" << k << "] is " << q[k] << "; every entry must be finite";
        throw std::invalid_argument(msg.str());
      }
    }
    if (pinocchio::isNormalized(model, q, 1e-6))
      return;
    // Test each joint's unit-norm part (quaternion, cos/sin pair) alone, inside a neutral
    // configuration, so that the message names the joint at fault.
    const Eigen::VectorXd neutral = pinocchio::neutral(model);
    Eigen::VectorXd probe = neutral;
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    {
      const int iq = model.idx_qs[j], nq = model.nqs[j];
      probe.segment(iq, nq) = q.segment(iq, nq);
      if (!pinocchio::isNormalized(model, probe, 1e-6))
      {
        const Eigen::Array<bool, Eigen::Dynamic, 1> unit = unitNormEntries(model, j, neutral);
        double squared = 0.;
        for (int k = 0; k < nq; ++k)
          if (unit[k])
            squared += q[iq + k] * q[iq + k];
        std::ostringstream msg;
        msg << name << "[" << iq << ":" << iq + nq << "] (joint '" << model.names[j] << "', "
            << model.joints[j].shortname() << ") = [" << q.segment(iq, nq).transpose()
            << "] holds a quaternion or cos/sin pair of norm " << std::sqrt(squared)
            << "; it must be 1 within 1e-6 (e.g. pinocchio.normalize)";
        throw std::invalid_argument(msg.str());
      }
      probe.segment(iq, nq) = neutral.segment(iq, nq);
    }
  }

  void checkVelocity(const pinocchio::Model & model, const Eigen::VectorXd & v, const char * name)
  {
    // The message is built only on an error: a stream costs more than a small solve's step.
    if (v.size() == model.nv && v.allFinite())
      return;
    std::ostringstream msg;
    if (v.size() != model.nv)
      msg << name << " must have model.nv = " << model.nv << " entries, got " << v.size();
    else
      for (Eigen::Index k = 0; k < v.size() && msg.tellp() == 0; ++k)
        if (!std::isfinite(v[k]))
          msg << name << "[" << k << "] is " << v[k] << "; every entry must be finite";
    throw std::invalid_argument(msg.str());
  }

  void checkMassMatrix(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q)
  {
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    prebuilt::aba(model, data, q, zero, zero);
    if (data.ddq.allFinite())
      return;
    prebuilt::crba(model, data, q);
    const Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M);
    std::ostringstream msg;
    msg << "the joint space inertia matrix M(q0) is singular (smallest eigenvalue "
        << eig.eigenvalues()[0] << ", largest " << eig.eigenvalues()[model.nv - 1]
        << "): moving the joints";
    const Eigen::VectorXd phi = eig.eigenvectors().col(0).cwiseAbs();
    const char * sep = " ";
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
      if (phi.segment(model.idx_vs[j], model.nvs[j]).maxCoeff() > 1e-3 * phi.maxCoeff())
      {
        msg << sep << "'" << model.names[j] << "'";
        sep = ", ";
      }
    msg << " together moves no mass, so the dynamics are undefined. Give every moving link an "
           "<inertial> with mass and inertia (a floating base needs a root link with mass)";
    throw std::invalid_argument(msg.str());
  }

  namespace
  {
    // Tangent coordinates (first index, count) along which a root joint moves its whole subtree
    // in a straight line, or count 0: a helical or revolute root turns it.
    std::pair<int, int> rootTranslation(const pinocchio::Model & model, pinocchio::JointIndex j)
    {
      const std::string kind = model.joints[j].shortname();
      int count = 0;
      if (kind == "JointModelFreeFlyer" || kind == "JointModelTranslation")
        count = 3;
      else if (kind == "JointModelPlanar")
        count = 2;
      else if (
        kind == "JointModelPX" || kind == "JointModelPY" || kind == "JointModelPZ"
        || kind == "JointModelPrismaticUnaligned")
        count = 1;
      return {model.idx_vs[j], count};
    }

    // Whether a loop or coupling ties root's subtree to the world or to another branch.
    bool loopsTie(
      const pinocchio::Model & model, const LoopConstraints & loops, pinocchio::JointIndex root)
    {
      for (const Loop & loop : loops.loops())
        if (isInSubtree(model, loop.joint_a, root) != isInSubtree(model, loop.joint_b, root))
          return true;
      for (const JointCoupling & coupling : loops.couplings())
        if (
          coupling.follower == root || coupling.leader == root
          || isInSubtree(model, coupling.follower, root)
               != isInSubtree(model, coupling.leader, root))
          return true;
      return false;
    }

    // Whether anything ties root's subtree to the world: an element (ForceModel::tiesToWorld),
    // a loop or coupling, or a stop on root itself.
    bool isTied(
      const pinocchio::Model & model,
      pinocchio::JointIndex root,
      const ForceModel * forces,
      const LoopConstraints * loops,
      const JointStops * stops)
    {
      if (forces != nullptr && !forces->empty() && forces->tiesToWorld(model, root))
        return true;
      if (loops != nullptr && loopsTie(model, *loops, root))
        return true;
      if (stops != nullptr)
        for (const JointStops::Stop & stop : stops->stops())
          if (stop.joint == root)
            return true;
      return false;
    }

    // The mass (kg) and the number of bodies of root's subtree.
    std::pair<double, int> weighSubtree(const pinocchio::Model & model, pinocchio::JointIndex root)
    {
      double mass = 0.;
      int bodies = 0;
      for (pinocchio::JointIndex j = root; j < static_cast<pinocchio::JointIndex>(model.njoints);
           ++j)
        if (isInSubtree(model, j, root))
        {
          mass += model.inertias[j].mass();
          ++bodies;
        }
      return {mass, bodies};
    }
  } // namespace

  std::string explainFreeFall(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const LoopConstraints * loops,
    const JointStops * stops)
  {
    Eigen::VectorXd tau;
    for (pinocchio::JointIndex root = 1; root < static_cast<pinocchio::JointIndex>(model.njoints);
         ++root)
    {
      const std::pair<int, int> along = rootTranslation(model, root);
      if (model.parents[root] != 0 || along.second == 0)
        continue;
      if (isTied(model, root, forces, loops, stops))
        continue;
      // Nothing ties the subtree to the world: the net force on it (its weight and the loads)
      // is the same in every pose, and its component along the root's translation is the
      // static force there.
      if (tau.size() == 0)
        tau = computeStaticForce(model, data, q, forces);
      const double pull = tau.segment(along.first, along.second).norm();
      const auto [mass, bodies] = weighSubtree(model, root);
      if (!(pull > 1e-9 * mass * model.gravity.linear().norm()) || pull == 0.)
        continue;
      std::ostringstream msg;
      msg.precision(4);
      msg << "the potential energy falls without bound: nothing holds joint '" << model.names[root]
          << "' (" << model.joints[root].shortname().substr(10) << " at the root, " << bodies
          << (bodies == 1 ? " body, " : " bodies, ") << mass
          << " kg): the net force along its free translation, " << pull
          << " N (weight and loads), is the same in every pose, so it falls whatever its joints "
             "do; fix its root or add what holds it (a spring, a loop, a stop)";
      return msg.str();
    }
    return "";
  }

  double restEnergyLimit(const pinocchio::Model & model, const Settings & settings)
  {
    // The energy the stopping rule accepts still moving, kRestEnergyFactor times over; a floor of
    // round-off for max_e = 0 (a rest at round-off leaves about (1e-15 of the force scale)^2).
    return std::max(
      kRestEnergyFactor * settings.max_e, 1e-24 * computeGravityScale(model) + 1e-300);
  }

  Solver::Solver(
    const pinocchio::Model & model,
    const LoopConstraints * loops,
    const JointStops * stops,
    const GroundContacts * contacts)
  : data(makeData(model, "the solver"))
  , model_(model)
  , constraints_(model, loops, stops, contacts)
  , work_(model)
  , window_(1, 0.)
  , step_control_(model, constraints_.loops(), constraints_.allowsStiffModeScaling())
  {
  }

  Solver::~Solver() = default;

  Solver::Workspace::Workspace(const pinocchio::Model & model)
  : q(model.nq)
  , v(model.nv)
  , dq(model.nv)
  , q_next(model.nq)
  , tau(Eigen::VectorXd::Zero(model.nv))
  , q_before(model.nq)
  , q_before2(model.nq)
  , q_runaway(model.nq)
  , fext(model.joints.size(), pinocchio::Force::Zero())
  {
  }

  Eigen::VectorXd Solver::staticForce(const Eigen::VectorXd & q, const ForceModel * forces)
  {
    return constraints_.computeStaticForce(data, q, forces);
  }

  StabilityReport Solver::assess(const Eigen::VectorXd & q, const ForceModel * forces)
  {
    return constraints_.assessStability(data, q, forces);
  }

  Result Solver::solve(
    const Eigen::VectorXd & q0,
    const Settings & settings,
    const ForceModel * forces,
    const AbortCallback & abort)
  {
    return solve(q0, Eigen::VectorXd::Zero(model_.nv), settings, forces, abort);
  }

  Result Solver::solve(
    const Eigen::VectorXd & q0,
    const Eigen::VectorXd & v0,
    const Settings & settings,
    const ForceModel * forces,
    const AbortCallback & abort)
  {
    RunClock clock; // the wall time includes the checks and the set-up
    Result result;
    start(q0, v0, settings, forces, result);
    const Status status =
      isFallingFreely(result) ? Status::NoEquilibrium : runLoop(clock, abort, result);
    finish(status, result);
    result.info.wall_time = clock.elapsed();
    return result;
  }

  bool Solver::isFallingFreely(Result & result)
  {
    result.reason = constraints_.explainFreeFall(data, work_.q, state_.forces);
    if (result.reason.empty())
      return false;
    // The trace holds the one state of the run, so that playback shows where it would fall.
    const std::pair<double, double> e = computeKineticEnergies(model_, data, work_.q, work_.v);
    trace_.sample(state_.step, state_.time, e.first, e.second, work_.q);
    return true;
  }

  Status Solver::runLoop(RunClock & clock, const AbortCallback & abort, Result & result)
  {
    clock.configure(*state_.settings, abort);
    RunProgress progress;
    progress.compute_residual = [this]() { return progressResidual(); };
    double energy = 0.; // of the last step, for the progress
    for (; state_.step < state_.settings->max_steps; ++state_.step)
    {
      if (clock.isDue(state_.step))
      {
        if (abort)
          measureProgress(energy, result, progress);
        if (const std::optional<Status> stop = clock.mustStop(progress))
          return *stop;
        reestimateStep();
      }
      if (const std::optional<Status> end = takeStep(result, energy))
      {
        ++state_.step; // a run that stops after evaluating the dynamics of a step counts it
        return *end;
      }
    }
    return Status::MaxSteps;
  }

  std::optional<Status> Solver::takeStep(Result & result, double & energy)
  {
    const StepEnergies e = evaluateDynamics();
    energy = e.exact;
    if (guard_.isDiverging(e.exact, e.simplified, data.ddq, peaks_.hasPrevious()))
      return rollBack(result) ? std::nullopt : std::optional<Status>(Status::Diverged);
    trace_.sample(state_.step, state_.time, e.exact, e.simplified, work_.q);
    switch (checkRunaway(e, result))
    {
    case Runaway::Fall:
      return Status::NoEquilibrium;
    case Runaway::Integration:
      return rollBack(result) ? std::nullopt : std::optional<Status>(Status::Diverged);
    case Runaway::None:
      break;
    }
    if (isAssessedAtRest(e))
    {
      if (rest_.accepts())
        return Status::Converged;
      if (rest_.isUnstable())
      {
        pushOff(result);
        return std::nullopt;
      }
    }
    if (peaks_.isPeak(e.signal))
    {
      damp(e, result);
      if (isSettledByNewton(result))
        return Status::Converged;
      return std::nullopt; // the next pass evaluates the dynamics at the damped state
    }
    peaks_.record(e.signal);
    if (state_.settings->backtrack)
      keepConfiguration(e.exact + e.added);
    if (!integrate() && !rollBack(result))
      return Status::Diverged;
    return std::nullopt;
  }

  void Solver::measureProgress(double energy, const Result & result, RunProgress & progress)
  {
    progress.steps = state_.step;
    progress.sim_time = state_.time;
    progress.kinetic_energy = energy;
    progress.peaks = result.info.peaks;
  }

  double Solver::progressResidual()
  {
    // In a Data of its own, made when first asked for: the run's scratch carries state between
    // steps. Where a second Data would not fit in memory, the progress goes without a residual.
    if (!progress_data_)
    {
      if (!fitsInMemory(model_, 1))
        return std::numeric_limits<double>::quiet_NaN();
      progress_data_ = std::make_unique<pinocchio::Data>(model_);
    }
    return residualOf(
      work_.q, constraints_.computeStaticForce(*progress_data_, work_.q, state_.forces));
  }

  void Solver::start(
    const Eigen::VectorXd & q0,
    const Eigen::VectorXd & v0,
    const Settings & settings,
    const ForceModel * forces,
    Result & result)
  {
    checkSettings(settings);
    checkSupportedModel(model_);
    if (model_.nv == 0)
      throw std::invalid_argument("model has no degree of freedom: nothing to settle");
    checkConfiguration(model_, q0, "q0");
    checkVelocity(model_, v0, "v0");
    checkMassMatrix(model_, data, q0);
    if (forces != nullptr && forces->empty())
      forces = nullptr; // nothing to apply: step exactly like the bare core

    // Set whole: nothing of a previous run is read in this one (a solver is reused).
    state_ = RunState();
    state_.settings = &settings;
    state_.forces = forces;
    state_.use_fext = forces != nullptr && forces->hasExternalForces();
    state_.kt = settings.kt;
    work_.q = q0;
    pinocchio::normalize(model_, work_.q); // q0 is normalised within 1e-6; make it exact
    work_.v = v0;
    work_.tau.setZero();
    constraints_.start(data, work_.q, work_.v, result.info);
    work_.q_before = work_.q;
    work_.q_before2 = work_.q;

    peaks_ = PeakDetector(settings.err);
    window_ = StoppingWindow(settings.ds, settings.max_e);
    rest_.start(
      std::max<std::int64_t>(settings.ds, model_.nv), std::max(10. * settings.max_e, 1e-30),
      settings.energy, restEnergyLimit(model_, settings));
    trace_.start(settings);
    runaway_.start(model_.nv, RunawayMonitor::kFirstSample, std::max(10. * settings.max_e, 1e-30));
    work_.q_runaway = work_.q;
    step_control_.start(settings, forces);
    if (step_control_.isAutomatic())
      runaway_.addRemoved(step_control_.estimate(data, work_.q, work_.v, state_.step));
    guard_.start(work_.q, work_.v, state_.time);
  }

  void Solver::reestimateStep()
  {
    if (!step_control_.isEstimateDue(work_.q, state_.step))
      return;
    const double loss = step_control_.estimate(data, work_.q, work_.v, state_.step);
    runaway_.addRemoved(loss);
    // Added inertia taken away takes its share of the energy at once: that drop is no peak of
    // the motion, and stopping there would stop a fall at such estimates.
    if (loss > 0.)
      peaks_.restart();
  }

  Solver::StepEnergies Solver::evaluateDynamics()
  {
    if (state_.forces != nullptr)
    {
      work_.tau.setZero();
      if (state_.use_fext)
        for (pinocchio::Force & f : work_.fext)
          f.setZero();
      state_.forces->computeForces(model_, data, work_.q, work_.v, work_.tau, work_.fext);
    }
    state_.locked = constraints_.lockedModel(step_control_, work_.q, work_.v);
    computeAcceleration(state_.locked != nullptr ? *state_.locked : step_control_.dynamicsModel());
    // Both measures every step, from the body velocities the dynamics just computed. With stiff
    // modes scaled, the exact signal includes their added inertia: it is the energy the scaled
    // system exchanges with its potential.
    StepEnergies e;
    const pinocchio::Convention convention = constraints_.dynamicsConvention();
    e.exact = computeBodyKineticEnergy(model_, data, convention);
    e.simplified = computeSimplifiedKineticEnergy(model_, data, convention);
    e.added = step_control_.addedEnergy(work_.v);
    e.signal = state_.settings->energy == EnergyMeasure::Exact ? e.exact + e.added : e.simplified;
    return e;
  }

  void Solver::computeAcceleration(const pinocchio::Model & model)
  {
    constraints_.computeAcceleration(
      model, data, work_.q, work_.v, work_.tau, state_.use_fext ? &work_.fext : nullptr);
  }

  void Solver::correctAcceleration()
  {
    if (state_.locked != nullptr)
    {
      // Stiff modes scaled at this step's peak would need the free model's dynamics.
      if (step_control_.stiffModes() == 0)
      {
        if (constraints_.acceptLocked(data, work_.q, work_.v))
          return;
        // Joints pulled off their stops leave them: once more with those free.
        if (const pinocchio::Model * unlocked = constraints_.unlockPulled(data, work_.q, work_.v))
        {
          computeAcceleration(*unlocked);
          if (constraints_.acceptLocked(data, work_.q, work_.v))
            return;
        }
      }
      computeAcceleration(step_control_.dynamicsModel()); // the free motion: hold() decides
    }
    // The scaled stiff modes' inertia enters the acceleration here, once the step is taken.
    step_control_.correctAcceleration(data);
    constraints_.hold(data, work_.q, work_.v, step_control_.timeScale());
  }

  void Solver::restartStretch()
  {
    peaks_.restart();
    window_.restart();
    guard_.restart();
    state_.stationary = false;
  }

  bool Solver::rollBack(Result & result)
  {
    if (!guard_.rollBack(work_.q, work_.v, state_.time))
    {
      result.reason = "the integration kept blowing up (non-finite values or explosive energy "
                      "growth) after the step was halved "
                      + std::to_string(DivergenceGuard::kMaxReductions) + " times";
      return false;
    }
    trace_.event(state_.step, state_.time, EventKind::Rollback);
    step_control_.halve(
      data, work_.q, work_.v, state_.step); // what it takes is forgotten by the reset below
    restartStretch();
    resetRunaway(0.);
    return true;
  }

  void Solver::resetRunaway(double e)
  {
    runaway_.reset(state_.step, e);
    work_.q_runaway = work_.q;
  }

  bool Solver::isMadeByIntegration()
  {
    // What gravity and the applied efforts did on the way: a fall releases about that much (the
    // dampers, stops and contacts only take energy away), a step too large for the mechanism
    // makes energy of its own and releases far more. Unknown work (NaN) is no evidence.
    double work = computeGravityPotentialEnergy(model_, data, work_.q_runaway)
                  - computeGravityPotentialEnergy(model_, data, work_.q);
    if (state_.forces != nullptr)
      work += state_.forces->computeWork(model_, data, work_.q_runaway, work_.q, runaway_.motion());
    return runaway_.released() > kRunawayWorkFactor * std::max(work, 0.) + runaway_.floor();
  }

  Solver::Runaway Solver::checkRunaway(const StepEnergies & e, Result & result)
  {
    if (!runaway_.isDue(state_.step) || !runaway_.sample(e.exact + e.added))
      return Runaway::None;
    // Partial damping can lose to a potential that falls by a fixed amount per turn although a
    // well exists (a pendulum under a constant torque just below what gravity holds): the first
    // verdict lowers kt to 0, which stops the mechanism at every peak, near the bottom of each
    // well it passes; only a second runaway is reported.
    if (state_.kt > 0.)
    {
      state_.kt = 0.;
      result.reason = "kt lowered to 0: with partial damping the released energy kept growing";
      resetRunaway(e.exact);
      return Runaway::None;
    }
    if (isMadeByIntegration())
      return Runaway::Integration;
    std::ostringstream msg;
    msg.precision(3);
    msg << "the potential energy falls without bound: " << runaway_.released() << " J released and "
        << runaway_.drift() << " (rad or m) travelled by "
        << describeCoordinate(model_, runaway_.furthestCoordinate()) << " in "
        << runaway_.stepsSinceReset(state_.step)
        << " steps with kt = 0, the energy released per doubling of the run and the distance both "
           "growing at least "
        << RunawayMonitor::kRunawayRatio << "x, " << RunawayMonitor::kRunawayDoublings
        << " times in a row";
    result.reason = msg.str();
    return Runaway::Fall;
  }

  bool Solver::isAssessedAtRest(const StepEnergies & e)
  {
    window_.record(e.signal);
    const bool quiet = window_.isQuiet(e.signal);
    const bool exact_rest = state_.stationary || window_.isExactRest();
    if (!rest_.isDue(quiet, peaks_.isNotRising(e.signal), exact_rest, state_.step))
      return false;
    // Where the mechanism is drifting (its velocity, or from rest its acceleration): a push off
    // an unstable rest goes that way, as the mechanism would fall, not along whichever sign
    // the eigen-solver gave the softest direction.
    work_.drift = work_.v.isZero(0.) ? data.ddq : work_.v;
    StabilityReport report = assess(work_.q, state_.forces);
    // Unstable, or loops left open, is no rest.
    const double energy =
      report.verdict == Stability::Unstable || !constraints_.isSatisfied(data, work_.q)
        ? std::numeric_limits<double>::infinity()
        : computeRestEnergy(report, staticForce(work_.q, state_.forces));
    rest_.record(std::move(report), work_.q, state_.step, energy);
    return true;
  }

  void Solver::pushOff(Result & result)
  {
    rest_.push(model_, data, work_.q, work_.v);
    if (work_.v.dot(work_.drift) < 0.)
      work_.v = -work_.v;
    ++result.info.pushes;
    trace_.event(state_.step, state_.time, EventKind::Push);
    guard_.keep(work_.q, work_.v, state_.time);
    step_control_.restartGrowth();
    restartStretch();
    // The runaway monitor runs on across a push: a fall off a saddle into a basin releases a
    // bounded energy, which no run of doublings mistakes for a runaway, while a mechanism that
    // is pushed again and again on its way down (a ball rolling down a slope, stopped dead at
    // each peak and read as unstable where it stood) would never be told to have none.
  }

  void Solver::damp(const StepEnergies & e, Result & result)
  {
    ++result.info.peaks;
    trace_.event(state_.step, state_.time, EventKind::Damping);
    double taken = e.exact + e.added;
    // Moved back to the peak, the mechanism gives up the potential it lost since too: at least
    // the kinetic energy of the peak sample is taken out (the runaway monitor counts it).
    if (state_.settings->backtrack && backtrackToPeak(e.signal, e.exact + e.added))
      taken = std::max(taken, state_.exact_before);
    work_.v *= state_.kt;
    runaway_.addRemoved((1. - state_.kt * state_.kt) * taken);
    // Impacts after a damping event start a new stretch: only steps in a row within one
    // stretch are chatter. Counted across events, a weld-hung arm whose fast mode peaks every
    // 4 steps, each stretch starting with its joints settling back onto their stops, had its
    // step halved 21 times and never got to a rest (gymnasium-robotics' Fetch).
    state_.impacts = 0;
    peaks_.restart();
    guard_.keepIfClean(work_.q, work_.v, state_.time);
    step_control_.restartGrowth();
    reestimateStep();
  }

  void Solver::keepConfiguration(double exact)
  {
    work_.q_before2.swap(work_.q_before);
    work_.q_before = work_.q;
    state_.exact_before = exact;
  }

  bool Solver::backtrackToPeak(double e, double exact)
  {
    // Moving back helps only if the exact energy is falling too: the simplified signal (masses
    // left out) may peak where the real motion still gains speed, and moving back there undoes
    // its progress at every such peak (with kt = 0 a 1e8 mass ratio then cycled for ever). At
    // a peak of the exact signal this always holds.
    if (!(exact < state_.exact_before))
      return false;
    // A sample pairs q_k with the velocity of the step into it, work_.v{k-1/2}: the energy's
    // vertex, stepsPastPeak samples back, lies half a step earlier along the path, between the two
    // configurations kept before this one (1 to 2 steps back).
    const double back = std::clamp(peaks_.stepsPastPeak(e) + 0.5, 1., 2.);
    pinocchio::interpolate(model_, work_.q_before, work_.q_before2, back - 1., work_.q);
    constraints_.projectState(data, work_.q, work_.v);
    // The clock is not moved back: it counts the time integrated, and the trace, the progress
    // reports and playback (keyframes in time order) need it to run forward.
    return true;
  }

  bool Solver::integrate()
  {
    const bool from_rest = (work_.v.array() == 0.).all();
    correctAcceleration();
    const double h = step_control_.nextStep(work_.v, data.ddq);
    constraints_.resolveContacts(data, work_.q, work_.v, h);
    integrateSemiImplicitEuler(model_, work_.q, work_.v, data.ddq, h, work_.dq, work_.q_next);
    if (!work_.q_next.allFinite() || !work_.v.allFinite())
      return false;
    work_.q.swap(work_.q_next);
    // A joint past a stop at every step is not motion but chatter (each step crosses the range,
    // and the impacts keep the energy at zero): roll back with the step halved, as for a
    // blow-up.
    const bool hit = constraints_.enforceStops(work_.q, work_.v, trace_.isTracing(), work_.dq);
    state_.impacts = hit ? state_.impacts + 1 : 0;
    for (const pinocchio::JointIndex joint : constraints_.hits())
      trace_.event(state_.step, state_.time + h, EventKind::Impact, joint);
    if (state_.impacts >= DivergenceGuard::kBlowUpSteps)
    {
      state_.impacts = 0;
      return false;
    }
    constraints_.projectStep(data, work_.q, work_.v, hit); // back onto the loops, the stops kept
    runaway_.addMotion(work_.dq);
    state_.time += h;
    // At rest before and after, and not moved to the bit: the next step starts from the same
    // state, so every later one would too (the loop is deterministic in q and v).
    state_.stationary = from_rest && (work_.v.array() == 0.).all() && work_.q == work_.q_next;
    return true;
  }

  void Solver::finish(Status status, Result & result)
  {
    result.status = status;
    result.info.steps = state_.step;
    result.info.sim_time = state_.time;
    result.info.dt = step_control_.dt();
    result.info.dt_estimates = step_control_.estimates();
    result.info.dt_reductions = guard_.reductions();
    result.info.scaled_modes = step_control_.scaledModes();
    result.info.scaled_joints = step_control_.scaledJoints();
    trace_.finish(result.trace);
    result.q = work_.q;
    result.v = work_.v;
    Eigen::VectorXd tau = staticForce(work_.q, state_.forces); // at result.q, polished or not
    result.residual = residualOf(work_.q, tau);
    if (!state_.settled_by_newton) // else it holds the residual where Newton took over
      result.info.residual_before_polish = result.residual;
    StabilityReport report =
      rest_.isAssessed(work_.q) ? rest_.takeReport() : assess(work_.q, state_.forces);
    if (state_.settings->polish && status == Status::Converged && !state_.settled_by_newton)
      polish(report, state_.forces, tau, result);
    const std::pair<double, double> energies =
      computeKineticEnergies(model_, data, result.q, work_.v);
    result.info.kinetic_energy = energies.first;
    result.info.simplified_kinetic_energy = energies.second;
    result.stability = report.verdict;
    result.info.min_stiffness_eigenvalue = report.min_eigenvalue;
    result.info.neutral_directions = report.neutral_directions;
    constraints_.describeRest(data, result.q, tau, result);
    state_.settings = nullptr;
    state_.forces = nullptr;
  }

  double Solver::residualOf(const Eigen::VectorXd & q, const Eigen::VectorXd & tau)
  {
    return constraints_.computeResidual(data, q, tau);
  }

  bool Solver::isAtRoundOff(double step, double last_step, const Eigen::VectorXd & q)
  {
    // The next step would be about step * (step / last_step) (linear convergence at the last
    // rate; Newton's quadratic one only falls faster): once that is below the round-off of q,
    // a further iteration cannot move the answer, only chase the residual into denormals (a
    // chain hanging straight down, whose gravity torques are exactly sin(q) ~ q).
    const double next = last_step > 0. ? step * std::min(1., step / last_step) : step;
    return next <= kRoundOffStep * std::max(1., q.lpNorm<Eigen::Infinity>());
  }

  double Solver::newtonReach(const StabilityReport & report, double residual)
  {
    // The correction a rest in a basin needs is about residual / (smallest stiffness): allow ten
    // times that and no more, so that Newton cannot wander to another stationary point.
    for (Eigen::Index k = 0; k < report.eigenvalues.size(); ++k)
      if (report.eigenvalues[k] > report.tolerance)
        return 10. * residual / report.eigenvalues[k];
    return -1.;
  }

  Eigen::VectorXd Solver::newtonStep(
    const StabilityReport & here, const StabilityReport & report, const Eigen::VectorXd & tau)
  {
    // Least squares with a rank cut: neutral directions (K singular there) are left alone.
    const double cut =
      std::max(report.tolerance / std::max(report.max_abs_eigenvalue, 1e-300), 1e-12);
    if (constraints_.empty())
      return -solveWithRankCut(here.stiffness, tau, cut);
    return -here.basis * solveWithRankCut(here.stiffness, here.basis.transpose() * tau, cut);
  }

  bool Solver::takeNewtonStep(
    NewtonRun & run,
    const Eigen::VectorXd & dq,
    const ForceModel * forces,
    Eigen::VectorXd & q_next)
  {
    // A full step overshoots where the stiffness changes fast along it (baxter's wrists, soft
    // under gravity: its residual of 8.1e-5 N m rose to 1.8e-4 and the rest was left
    // unpolished): halved until the residual falls, as a guarded Newton does.
    double fraction = 1.;
    for (int halving = 0; halving <= kNewtonHalvings; ++halving, fraction *= 0.5)
    {
      pinocchio::integrate(model_, run.q, fraction * dq, q_next);
      // A step the constraints cannot follow (loops held open by the stops) is no step to a
      // rest.
      if (!constraints_.projectConfiguration(data, q_next))
        continue;
      Eigen::VectorXd tau_next = staticForce(q_next, forces);
      const double residual_next = residualOf(q_next, tau_next);
      if (!(residual_next < run.residual))
        continue;
      run.q.swap(q_next);
      run.tau = std::move(tau_next);
      run.residual = residual_next;
      return true;
    }
    return false;
  }

  bool Solver::isStalledAtRoundOff(
    const NewtonRun & run,
    const Eigen::VectorXd & dq,
    double last_step,
    const Eigen::VectorXd & tau0) const
  {
    // A step that no longer lowers a residual at the round-off of the forces, and at the rate of
    // the last one below the round-off of q: Newton has converged (a quadratic stride can land
    // there before iterateNewton's own test sees a small step). A stall short of it (a reaction
    // Newton cannot balance: a car on its tyres at 1e-4 N) is no rest.
    const double forces_scale =
      std::max(tau0.lpNorm<Eigen::Infinity>(), computeGravityScale(model_));
    return isAtRoundOff(dq.lpNorm<Eigen::Infinity>(), last_step, run.q)
           && run.residual <= kHeldResidual * forces_scale;
  }

  Solver::NewtonRun Solver::iterateNewton(
    const Eigen::VectorXd & q0,
    const Eigen::VectorXd & tau0,
    double residual0,
    const StabilityReport & report,
    const ForceModel * forces,
    double max_move)
  {
    NewtonRun run{q0, tau0, residual0, 0, false};
    Eigen::VectorXd q_next(model_.nq);
    // Constraints restrict the motions Newton may take (the report's basis).
    const bool restricted = !constraints_.empty();
    double last_step = 0.; // |dq|_inf of the step taken before
    StabilityReport at;    // the stiffness (and with constraints the basis) at q
    for (; run.iterations < 10 && run.residual > 0.; ++run.iterations)
    {
      // The first iteration starts where the report was drawn: its K and B.
      if (run.iterations > 0 && restricted)
        at = assess(run.q, forces);
      else if (run.iterations > 0)
        at.stiffness = computeStiffnessMatrix(model_, data, run.q, forces);
      const StabilityReport & here = run.iterations == 0 ? report : at;
      if (restricted && here.basis.cols() == 0)
      {
        // The constraints hold every motion (the rocker of a four-bar pressed on its stop):
        // nothing is left to move, a zero step would only be counted a stall, and their forces
        // balance the rest to round-off.
        run.at_round_off = here.verdict == Stability::Stable
                           && run.residual <= kHeldResidual * run.tau.lpNorm<Eigen::Infinity>();
        break;
      }
      const Eigen::VectorXd dq = newtonStep(here, report, run.tau);
      if (!takeNewtonStep(run, dq, forces, q_next))
      {
        run.at_round_off = isStalledAtRoundOff(run, dq, last_step, tau0);
        break;
      }
      if (
        max_move < std::numeric_limits<double>::infinity()
        && pinocchio::difference(model_, q0, run.q).lpNorm<Eigen::Infinity>() > max_move)
      {
        ++run.iterations;
        return run; // out of reach: not at round-off, whatever the residual
      }
      const double step = dq.lpNorm<Eigen::Infinity>();
      if (isAtRoundOff(step, last_step, run.q))
      {
        ++run.iterations;
        run.at_round_off = true;
        break;
      }
      last_step = step;
    }
    run.at_round_off = run.at_round_off || run.residual == 0.;
    return run;
  }

  void Solver::polish(
    StabilityReport & report, const ForceModel * forces, Eigen::VectorXd & tau_q, Result & result)
  {
    const double reach = newtonReach(report, result.residual);
    if (reach < 0.)
      return;
    NewtonRun run = iterateNewton(result.q, tau_q, result.residual, report, forces);
    result.info.polish_iterations = run.iterations;
    if (run.iterations == 0)
      return;
    const double moved = pinocchio::difference(model_, result.q, run.q).lpNorm<Eigen::Infinity>();
    StabilityReport after = assess(run.q, forces);
    if (moved > reach || after.verdict != report.verdict)
      return;
    result.q = run.q;
    result.residual = run.residual;
    result.info.polished = true;
    tau_q = run.tau;
    report = std::move(after);
  }

  bool Solver::isSettledByNewton(Result & result)
  {
    // A try costs O(nv^3), a step O(nv): the step estimates' spacing, without their ds floor.
    const std::int64_t spacing =
      std::max<std::int64_t>(1, static_cast<std::int64_t>(model_.nv) * model_.nv / 4);
    if (
      !state_.settings->polish || !state_.settings->newton_takeover
      || state_.step - state_.newton_tried_at < spacing)
      return false;
    state_.newton_tried_at = state_.step;
    std::optional<Takeover> took = takeOver(work_.q, *state_.settings, state_.forces);
    if (!took)
      return false;
    result.info.residual_before_polish = took->residual_from;
    result.info.polish_iterations = took->run.iterations;
    result.info.polished = took->run.iterations > 0;
    work_.q = std::move(took->run.q);
    work_.v.setZero();
    rest_.record(std::move(took->report), work_.q, state_.step, took->energy);
    state_.settled_by_newton = true;
    return true;
  }

  std::optional<Solver::Takeover> Solver::takeOver(
    const Eigen::VectorXd & q, const Settings & settings, const ForceModel * forces)
  {
    StabilityReport report = assess(q, forces);
    if (report.verdict == Stability::Unstable)
      return std::nullopt;
    const Eigen::VectorXd tau = staticForce(q, forces);
    const double residual = residualOf(q, tau);
    // Within the polish's reach and near where the mechanism stands: far from its rest the
    // reach (residual over the softest stiffness) is long, and Newton, clamped onto a stop,
    // found a 'rest' 2.8 rad away and 3.7 J above the start of a bistable pendulum's release.
    // With every motion held there is no stiffness to tell a reach: iterateNewton decides.
    const bool held = !constraints_.empty() && report.basis.cols() == 0;
    const double reach =
      held ? kTakeoverReach : std::min(newtonReach(report, residual), kTakeoverReach);
    if (reach < 0.)
      return std::nullopt;
    // Only a Newton run that gets to round-off within the reach (iterateNewton gives up as soon
    // as it moves further) ends the run: anything less (a stall, a step beyond the reach,
    // another kind of rest) leaves the mechanism to the damping, where it was.
    NewtonRun run = iterateNewton(q, tau, residual, report, forces, reach);
    if (!run.at_round_off)
      return std::nullopt;
    // Not moved (held, or a zero residual): the rest is the one just assessed.
    StabilityReport after = run.iterations == 0 ? report : assess(run.q, forces);
    if (after.verdict != report.verdict)
      return std::nullopt;
    // Newton leaves neutral directions alone: a force still pulling along one (a slider on a
    // tilted arm, 3.6 N along it) is no rest, whatever the round-off of the rest.
    const double energy = computeRestEnergy(after, run.tau);
    if (!(energy <= restEnergyLimit(model_, settings)))
      return std::nullopt;
    return Takeover{std::move(run), std::move(after), residual, energy};
  }

  void Solver::checkNewtonEntry(const Eigen::VectorXd & q, const char * who) const
  {
    if (!constraints_.empty())
      throw std::logic_error(
        std::string(who)
        + " works on a mechanism without constraints: loops, stops and contacts keep a state "
          "that belongs to a run (use solve)");
    checkSupportedModel(model_);
    checkConfiguration(model_, q, "q");
  }

  std::optional<Solver::NewtonRest> Solver::settleByNewton(
    const Eigen::VectorXd & q, const Settings & settings, const ForceModel * forces)
  {
    checkNewtonEntry(q, "settleByNewton");
    checkSettings(settings);
    std::optional<Takeover> took = takeOver(q, settings, forces);
    if (!took)
      return std::nullopt;
    return NewtonRest{
      std::move(took->run.q), took->run.residual, took->residual_from, took->run.iterations,
      took->report.verdict};
  }

  Solver::NewtonRest Solver::polishRest(const Eigen::VectorXd & q, const ForceModel * forces)
  {
    checkNewtonEntry(q, "polishRest");
    Result rest;
    rest.q = q;
    Eigen::VectorXd tau = staticForce(q, forces);
    rest.residual = residualOf(q, tau);
    StabilityReport report = assess(q, forces);
    const double from = rest.residual;
    polish(report, forces, tau, rest);
    const int iterations = rest.info.polished ? rest.info.polish_iterations : 0;
    return NewtonRest{std::move(rest.q), rest.residual, from, iterations, report.verdict};
  }

} // namespace pinsettle
