//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/solver.hpp"
#include "pinsettle/energy.hpp"
#include "pinsettle/stability.hpp"
#include "loop-stepper.hpp"

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <limits>
#include <chrono>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>

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
        // The unit-norm entries are those that normalize changes in a segment of ones.
        probe.segment(iq, nq).setOnes();
        pinocchio::normalize(model, probe);
        double squared = 0.;
        for (int k = 0; k < nq; ++k)
          if (probe[iq + k] != 1.)
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
    std::ostringstream msg;
    if (v.size() != model.nv)
      msg << name << " must have model.nv = " << model.nv << " entries, got " << v.size();
    else
      for (Eigen::Index k = 0; k < v.size() && msg.tellp() == 0; ++k)
        if (!std::isfinite(v[k]))
          msg << name << "[" << k << "] is " << v[k] << "; every entry must be finite";
    if (msg.tellp() > 0)
      throw std::invalid_argument(msg.str());
  }

  void checkMassMatrix(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q)
  {
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    pinocchio::aba(model, data, q, zero, zero);
    if (data.ddq.allFinite())
      return;
    pinocchio::crba(model, data, q);
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

  Eigen::VectorXd computeStaticForce(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    if (!forces || forces->empty())
      return pinocchio::computeGeneralizedGravity(model, data, q);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
    forces->computeForces(model, data, q, zero, tau, fext);
    if (forces->hasExternalForces())
      return pinocchio::rnea(model, data, q, zero, zero, fext) - tau;
    return pinocchio::computeGeneralizedGravity(model, data, q) - tau;
  }

  double computeStaticResidual(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    return computeStaticForce(model, data, q, forces).lpNorm<Eigen::Infinity>();
  }

  Solver::Solver(const pinocchio::Model & model, const LoopConstraints * loops)
  : data(model)
  , model_(model)
  , loops_(loops != nullptr && !loops->empty() ? loops : nullptr)
  , q_(model.nq)
  , v_(model.nv)
  , dq_(model.nv)
  , q_next_(model.nq)
  , tau_(Eigen::VectorXd::Zero(model.nv))
  , fext_(model.joints.size(), pinocchio::Force::Zero())
  {
    if (loops_ != nullptr)
    {
      if (&loops_->model() != &model)
        throw std::invalid_argument("loops: they were made for another model than the solver's");
      stepper_.reset(new LoopStepper(model, *loops_));
    }
  }

  Solver::~Solver() = default;

  Eigen::VectorXd Solver::staticForce(const Eigen::VectorXd & q, const ForceModel * forces)
  {
    if (loops_ != nullptr)
      return computeStaticForce(model_, data, *loops_, q, forces);
    return computeStaticForce(model_, data, q, forces);
  }

  StabilityReport Solver::assess(const Eigen::VectorXd & q, const ForceModel * forces)
  {
    if (loops_ != nullptr)
      return assessStability(model_, data, *loops_, q, forces);
    return assessStability(model_, data, q, forces);
  }

  Result Solver::solve(
    const Eigen::VectorXd & q0,
    const Settings & settings,
    const ForceModel * forces,
    const AbortCallback & abort)
  {
    return solve(q0, Eigen::VectorXd::Zero(model_.nv), settings, forces, abort);
  }

  namespace
  {
    // Keeps every other sample so that a full trace covers the run at twice the stride.
    void decimate(std::vector<TraceSample> & trace)
    {
      std::size_t kept = 0;
      for (std::size_t k = 0; k < trace.size(); k += 2)
        trace[kept++] = trace[k];
      trace.resize(kept);
    }
  } // namespace

  namespace
  {
    // Kinetic energy ratio between consecutive steps, held for kBlowUpSteps steps in a row,
    // that no resolved motion produces: with dt <= 2 / omega_max a physical instability grows
    // the energy at most e^2 per step; the explicit integrator past its limit grows it faster.
    constexpr double kBlowUpRatio = 10.;
    constexpr int kBlowUpSteps = 10;
    // Energies beyond this are treated like non-finite values (they soon are).
    constexpr double kHugeEnergy = 1e150;
    // Step halvings before the run is declared diverged.
    constexpr int kMaxReductions = 30;
    // Runaway test: the energy released and the distance travelled since the last reset must
    // both grow by kRunawayRatio or more over each of kRunawayDoublings consecutive doublings of
    // the run length.
    constexpr double kRunawayRatio = 1.5;
    constexpr int kRunawayDoublings = 10;
    // The automatic step is re-estimated once the configuration moved this far (rad or m)
    // since the last estimate.
    constexpr double kFarMove = 0.1;
    // Whether q is farther than distance (rad or m, max norm) from q_ref; work holds the tangent
    // difference (dim model.nv), so that nothing is allocated.
    bool movedBeyond(
      const pinocchio::Model & model,
      const Eigen::VectorXd & q_ref,
      const Eigen::VectorXd & q,
      Eigen::VectorXd & work,
      double distance)
    {
      pinocchio::difference(model, q_ref, q, work);
      return work.lpNorm<Eigen::Infinity>() > distance;
    }
    // Automatic step when nothing pulls, pushes or damps (its value does not matter then).
    constexpr double kRestStep = 1e-3;
  } // namespace

  Result Solver::solve(
    const Eigen::VectorXd & q0,
    const Eigen::VectorXd & v0,
    const Settings & settings,
    const ForceModel * forces,
    const AbortCallback & abort)
  {
    typedef std::chrono::steady_clock Clock;
    const Clock::time_point start = Clock::now();

    checkSettings(settings);
    if (model_.nv == 0)
      throw std::invalid_argument("model has no degree of freedom: nothing to settle");
    checkConfiguration(model_, q0, "q0");
    checkVelocity(model_, v0, "v0");
    checkMassMatrix(model_, data, q0);
    if (forces != nullptr && forces->empty())
      forces = nullptr; // nothing to apply: step exactly like the bare core

    const pinocchio::Model & model = model_;
    const double err = settings.err;
    const double max_e = settings.max_e;
    const bool exact = settings.energy == EnergyMeasure::Exact;
    const bool use_fext = forces != nullptr && forces->hasExternalForces();
    const bool check_clock = std::isfinite(settings.max_time);
    const bool tracing = settings.trace_every > 0;
    const bool auto_dt = settings.dt == 0.;
    double kt = settings.kt; // lowered to 0 when partial damping cannot hold a runaway

    Result result;
    q_ = q0;
    pinocchio::normalize(model, q_); // q0 is normalised within 1e-6; make it exact
    v_ = v0;
    result.mobility = model.nv;
    if (loops_ != nullptr)
    {
      // Closed mechanism: start assembled, with a velocity the loops allow.
      result.assembly_distance = assembleLoops(model, data, *loops_, q_);
      const LoopMotion motion = computeLoopMotion(model, data, *loops_, q_);
      result.mobility = static_cast<int>(motion.basis.cols());
      if (result.mobility == 0)
      {
        std::ostringstream msg;
        msg << "the loops leave the mechanism no degree of freedom (" << motion.rank
            << " independent loop equations on model.nv = " << model.nv
            << " joint velocities): it is a structure, with nothing to settle";
        throw std::invalid_argument(msg.str());
      }
      v_ = motion.basis * (motion.basis.transpose() * v_);
      stepper_->init(data, q_);
    }
    tau_.setZero();

    // Stopping window: the last ds samples of the driving energy, as a ring buffer.
    const std::size_t ds = static_cast<std::size_t>(settings.ds);
    window_.assign(ds, 0.);
    std::size_t window_pos = 0, window_count = 0;

    std::int64_t trace_stride = settings.trace_every;
    if (trace_stride > 0) // never more samples than the run can record
      result.trace.reserve(
        static_cast<std::size_t>(
          std::min(settings.trace_capacity, settings.max_steps / trace_stride + 1)));

    // e_prev2, e_prev: the two samples before the current one; fresh counts samples since the
    // last damping event (the three-sample rule needs three samples of one undamped stretch).
    double e_prev2 = 0., e_prev = 0.;
    int fresh = 0;
    // Steps in a row with exactly zero energy: a start at exact rest, where "energy decreasing"
    // never holds and the stopping rule alone would run to max_steps.
    std::int64_t still = 0;
    // Step of the last stability assessment.
    std::int64_t last_assessed = 0;
    double time = 0.;
    Status status = Status::MaxSteps;
    std::int64_t step = 0;
    StabilityReport report;

    // Time step: fixed, or estimated from the time scales and re-estimated after large moves.
    double dt = settings.dt, step_scale = 1.;
    double h = dt; // the step actually taken last (dt, or less while moving fast)
    std::int64_t estimated_at = 0;
    const std::int64_t estimate_spacing =
      std::max<std::int64_t>(settings.ds, static_cast<std::int64_t>(model.nv) * model.nv / 4);
    // Kinetic energy of the added inertia of the scaled stiff modes (J).
    const auto addedEnergy = [&](const TimeScale & scale) {
      if (scale.stiff_masses.size() == 0)
        return 0.;
      return 0.5 * (scale.stiff_momenta * v_).cwiseAbs2().dot(scale.stiff_masses);
    };
    double switch_loss = 0.; // kinetic energy taken when the scaled modes change (J)
    const auto estimateStep = [&]() {
      const double added_before = addedEnergy(time_scale_);
      time_scale_ = loops_ != nullptr
                      ? computeTimeScale(model, data, *loops_, q_, forces)
                      : computeTimeScale(model, data, q_, forces, settings.scale_stiff_modes);
      const TimeScale & scale = time_scale_;
      const Eigen::Index stiff = scale.stiff_masses.size();
      // New modes change the kinetic energy at the same velocity; never let that add energy
      // (it could pump the motion up, estimate after estimate): scale the velocity down
      // instead, as a damping event would. data.M is fresh from computeTimeScale's crba.
      const double added_after = addedEnergy(scale);
      if (added_after > added_before)
      {
        const double real = 0.5 * v_.dot(data.M.selfadjointView<Eigen::Upper>() * v_);
        const double ratio = (real + added_before) / (real + added_after);
        v_ *= std::sqrt(ratio);
        switch_loss += (1. - ratio) * (real + added_after);
      }
      else
        switch_loss += added_before - added_after;
      result.scaled_modes = std::max(result.scaled_modes, static_cast<int>(stiff));
      stiff_y_.resize(model.nv, stiff);
      stiff_s_.resize(stiff, stiff);
      stiff_z_.resize(stiff);
      stiff_p_.resize(stiff);
      stiff_llt_ = Eigen::LLT<Eigen::MatrixXd>(stiff);
      double next = std::isfinite(scale.critical_step)
                      ? settings.dt_safety * scale.critical_step * step_scale
                      : kRestStep * step_scale;
      if (result.dt_estimates > 0)
        next = std::min(next, 2. * dt); // grow gradually: the new estimate is local too
      dt = next;
      q_estimate_ = q_;
      estimated_at = step;
      ++result.dt_estimates;
    };
    const auto movedFar = [&]() {
      return step - estimated_at >= estimate_spacing
             && movedBeyond(model, q_estimate_, q_, moved_, kFarMove);
    };
    time_scale_ = TimeScale(); // no stiff-mode scaling with a fixed step
    if (auto_dt)
      estimateStep();

    // Divergence guard: the last good state (start, after each damping event or push). A damping
    // event becomes the new good state only if the stretch before it never grew the energy
    // kBlowUpRatio-fold in one step: an explosion can pass a peak before it is caught.
    q_good_ = q_;
    v_good_ = v_;
    double time_good = 0., e_exact_prev = 0.;
    int blow_up = 0;
    bool tainted = false;

    // Runaway test (no equilibrium): the energy released by the potential since the last reset,
    // the kinetic energy gained plus the energy taken out, sampled at doublings of the run.
    std::int64_t reset_step = 0, next_sample = settings.ds;
    double e_reset = 0., removed = 0., released_sample = 0., drift_sample = 0.;
    int growing = 0;
    // Net motion since the reset in tangent coordinates (a continuous joint unwrapped): a
    // runaway also travels ever further, where a mechanism ringing in place stays put.
    drift_.setZero(model.nv);
    moved_.resize(model.nv);
    const auto resetRunaway = [&](double e_now) {
      reset_step = step;
      next_sample = settings.ds;
      e_reset = e_now;
      removed = 0.;
      switch_loss = 0.;
      released_sample = 0.;
      drift_sample = 0.;
      growing = 0;
      drift_.setZero();
    };
    const auto restart = [&]() // samples of an interrupted stretch say nothing any more
    {
      still = 0;
      fresh = 0;
      window_count = 0;
      blow_up = 0;
      tainted = false;
    };

    // Back to the last good state with half the step; false once kMaxReductions are used up.
    const auto rollBack = [&]() {
      q_ = q_good_;
      v_ = v_good_;
      time = time_good;
      if (result.dt_reductions == kMaxReductions)
      {
        status = Status::Diverged;
        result.reason = "the integration kept blowing up (non-finite values or explosive energy "
                        "growth) after the step was halved "
                        + std::to_string(kMaxReductions) + " times";
        return false;
      }
      ++result.dt_reductions;
      if (tracing)
        result.events.push_back(TraceEvent{step, time, EventKind::Rollback});
      step_scale *= 0.5;
      dt *= 0.5;
      if (auto_dt) // the modes of the good state, and no longer step than the halved one
      {
        const double halved = dt;
        estimateStep();
        dt = std::min(dt, halved);
      }
      restart();
      resetRunaway(0.);
      return true;
    };

    for (; step < settings.max_steps; ++step)
    {
      if (step > 0 && step % settings.check_every == 0)
      {
        if (
          check_clock
          && std::chrono::duration<double>(Clock::now() - start).count() > settings.max_time)
        {
          status = Status::TimeLimit;
          break;
        }
        if (abort && abort())
        {
          status = Status::Aborted;
          break;
        }
        if (auto_dt && movedFar())
          estimateStep();
      }

      if (forces != nullptr)
      {
        tau_.setZero();
        if (use_fext)
          for (pinocchio::Force & f : fext_)
            f.setZero();
        forces->computeForces(model, data, q_, v_, tau_, fext_);
      }
      if (loops_ != nullptr)
        stepper_->dynamics(data, q_, v_, tau_, use_fext ? &fext_ : nullptr);
      else if (use_fext)
        pinocchio::aba(model, data, q_, v_, tau_, fext_);
      else
        pinocchio::aba(model, data, q_, v_, tau_);
      // Both measures every step, from the body velocities ABA just computed.
      const double e_exact = computeBodyKineticEnergy(model, data);
      const double e_simple = computeSimplifiedKineticEnergy(model, data);
      // With stiff modes scaled, the exact measure includes their added inertia: it is the
      // energy the scaled system exchanges with its potential.
      const Eigen::Index stiff = time_scale_.stiff_masses.size();
      double e_added = 0.;
      if (stiff > 0)
      {
        stiff_p_.noalias() = time_scale_.stiff_momenta * v_;
        e_added = 0.5 * stiff_p_.cwiseAbs2().dot(time_scale_.stiff_masses);
      }
      const double e = exact ? e_exact + e_added : e_simple;

      // Divergence guard: non-finite values, or an energy explosion no resolved motion makes.
      blow_up =
        fresh >= 1 && e_exact_prev > 0. && e_exact > kBlowUpRatio * e_exact_prev ? blow_up + 1 : 0;
      tainted = tainted || blow_up > 0;
      e_exact_prev = e_exact;
      if (
        !std::isfinite(e_exact) || !std::isfinite(e_simple) || e_exact > kHugeEnergy
        || !data.ddq.allFinite() || blow_up >= kBlowUpSteps)
      {
        if (!rollBack())
        {
          ++step;
          break;
        }
        continue;
      }

      if (trace_stride > 0 && step % trace_stride == 0)
      {
        if (result.trace.size() == static_cast<std::size_t>(settings.trace_capacity))
        {
          decimate(result.trace);
          trace_stride *= 2;
        }
        if (step % trace_stride == 0)
          result.trace.push_back(
            TraceSample{
              step, time, e_exact, e_simple,
              settings.trace_configurations ? q_ : Eigen::VectorXd()});
      }

      // No equilibrium: the energy released since the reset keeps growing (by kRunawayRatio or
      // more per doubling of the run, kRunawayDoublings times in a row): the potential falls
      // without bound along the motion. Partial damping can lose to a potential that falls by
      // a fixed amount per turn although a well exists (a pendulum under a constant torque just
      // below what gravity holds), so the first verdict lowers kt to 0, which stops the
      // mechanism at every peak, near the bottom of each well it passes; only a second runaway
      // is reported.
      if (step - reset_step == next_sample)
      {
        const double released = e_exact + e_added - e_reset + removed + switch_loss;
        const double drift = drift_.lpNorm<Eigen::Infinity>();
        growing = released_sample > 0. && released >= kRunawayRatio * released_sample
                      && drift_sample > 0. && drift >= kRunawayRatio * drift_sample
                    ? growing + 1
                    : 0;
        released_sample = released;
        drift_sample = drift;
        next_sample *= 2;
        if (growing >= kRunawayDoublings)
        {
          if (kt > 0.)
          {
            kt = 0.;
            result.reason = "kt lowered to 0: with partial damping the released energy kept "
                            "growing";
            resetRunaway(e_exact);
          }
          else
          {
            status = Status::NoEquilibrium;
            std::ostringstream msg;
            msg.precision(3);
            msg << "the potential energy falls without bound: " << released << " J released and "
                << drift << " (rad or m) travelled in " << (step - reset_step)
                << " steps with kt = 0, both growing at least " << kRunawayRatio
                << "x per doubling of the run " << kRunawayDoublings << " times in a row";
            result.reason = msg.str();
            ++step;
            break;
          }
        }
      }

      // Stopping rule: energy decreasing and the sum of the last ds samples <= max_e.
      window_[window_pos] = e;
      window_pos = (window_pos + 1) % ds;
      if (window_count < ds)
        ++window_count;
      const bool decreasing = fresh >= 1 && e < e_prev;
      // e <= max_e is necessary for the sum to be; the exact sum is only formed then, since a
      // running sum would keep the round-off of the early, large energies.
      const bool quiet = window_count == ds && e <= max_e
                         && std::accumulate(window_.begin(), window_.end(), 0.) <= max_e;
      // Exact rest for a whole window: the start is an equilibrium (stable or not), where
      // "energy decreasing" never holds.
      still = e == 0. ? still + 1 : 0;
      const bool exact_rest = still >= settings.ds;
      // Creeping: quiet but still rising, as on a start at rest a round-off away from a saddle
      // or a maximum; checked once a window, since a stable rest soon turns to decreasing.
      const bool creeping = quiet && !decreasing && step - last_assessed >= settings.ds;

      // At rest: accept a stable or neutral rest; from an unstable one (a saddle or a maximum)
      // push the mechanism along the most negative stiffness direction with a tiny energy
      // (10 max_e) and go on: it falls away to where it would really stay.
      if ((quiet && decreasing) || exact_rest || creeping)
      {
        report = assess(q_, forces);
        report_q_ = q_;
        last_assessed = step;
        if (report.verdict != Stability::Unstable && !creeping)
        {
          status = Status::Converged;
          ++step;
          break;
        }
        if (report.verdict == Stability::Unstable)
        {
          v_ = report.softest_direction;
          const std::pair<double, double> unit = computeKineticEnergies(model, data, q_, v_);
          const double e_unit = exact ? unit.first : unit.second;
          const double e_push = std::max(10. * max_e, 1e-30);
          v_ *= e_unit > 0. ? std::sqrt(e_push / e_unit) : 0.;
          ++result.pushes;
          if (tracing)
            result.events.push_back(TraceEvent{step, time, EventKind::Push});
          q_good_ = q_;
          v_good_ = v_;
          time_good = time;
          restart();
          resetRunaway(0.);
          continue;
        }
        // Creeping near a stable or neutral rest: not at rest yet, go on.
      }

      // Peak: the middle of the last three samples exceeds both neighbours by more than err
      // times itself.
      if (fresh >= 2 && e_prev - e_prev2 > err * e_prev && e_prev - e > err * e_prev)
      {
        ++result.peaks;
        if (tracing)
          result.events.push_back(TraceEvent{step, time, EventKind::Damping});
        if (settings.backtrack)
        {
          // Parabola through (-1, e_prev2), (0, e_prev), (1, e): its vertex lies x steps after
          // the middle sample; the current sample is 1 - x steps past the peak.
          const double x = (e_prev2 - e) / (2. * (e_prev2 - 2. * e_prev + e));
          const double back = (1. - x) * h;
          dq_.noalias() = -back * v_;
          pinocchio::integrate(model, q_, dq_, q_next_);
          q_.swap(q_next_);
          if (loops_ != nullptr)
            stepper_->project(data, q_, v_);
          time -= back;
        }
        v_ *= kt;
        removed += (1. - kt * kt) * (e_exact + e_added);
        fresh = 0;
        if (!tainted)
        {
          q_good_ = q_;
          v_good_ = v_;
          time_good = time;
        }
        if (auto_dt && movedFar())
          estimateStep();
        continue; // re-evaluate the dynamics at the damped state
      }
      e_prev2 = e_prev;
      e_prev = e;
      ++fresh;

      // Stiff modes scaled: the acceleration under M + W^T diag(d) W instead of M (Woodbury):
      // a' = a - Y (diag(d)^-1 + W Y)^-1 W a with Y = M^-1 W^T.
      if (stiff > 0)
      {
        const Eigen::MatrixXd & W = time_scale_.stiff_momenta;
        dq_ = data.ddq; // kept aside from computeMinverse's passes
        pinocchio::computeMinverse(model, data, q_);
        stiff_y_.noalias() = data.Minv.selfadjointView<Eigen::Upper>() * W.transpose();
        stiff_s_.noalias() = W * stiff_y_;
        stiff_s_.diagonal() += time_scale_.stiff_masses.cwiseInverse();
        stiff_llt_.compute(stiff_s_);
        stiff_z_.noalias() = W * dq_;
        stiff_llt_.solveInPlace(stiff_z_);
        data.ddq = dq_;
        data.ddq.noalias() -= stiff_y_ * stiff_z_;
      }

      // Semi-implicit Euler on the configuration manifold.
      // The automatic step also bounds the turn per step to dt_safety (rad or m): velocity-
      // dependent forces (Coriolis, centrifugal) stiffen fast motion, which K does not see.
      h = dt;
      if (auto_dt)
      {
        const double speed = v_.lpNorm<Eigen::Infinity>();
        if (speed * h > settings.dt_safety)
          h = settings.dt_safety / speed;
      }
      v_.noalias() += h * data.ddq;
      dq_.noalias() = h * v_;
      pinocchio::integrate(model, q_, dq_, q_next_);
      if (!q_next_.allFinite() || !v_.allFinite())
      {
        if (!rollBack())
        {
          ++step;
          break;
        }
        continue;
      }
      q_.swap(q_next_);
      if (loops_ != nullptr) // back onto the loops, and a velocity they allow
        stepper_->project(data, q_, v_);
      drift_ += dq_;
      time += h;
    }

    result.status = status;
    result.steps = step;
    result.sim_time = time;
    result.dt = dt;
    result.trace_stride = trace_stride;
    result.q = q_;
    result.v = v_;
    result.residual = staticForce(q_, forces).lpNorm<Eigen::Infinity>();
    result.residual_before_polish = result.residual;
    if (report.verdict == Stability::Unknown || report_q_ != q_)
      report = assess(q_, forces);
    if (settings.polish && status == Status::Converged)
      polish(report, forces, result);
    const std::pair<double, double> energies = computeKineticEnergies(model, data, result.q, v_);
    result.kinetic_energy = energies.first;
    result.simplified_kinetic_energy = energies.second;
    result.stability = report.verdict;
    result.min_stiffness_eigenvalue = report.min_eigenvalue;
    result.neutral_directions = report.neutral_directions;
    if (loops_ != nullptr)
      result.constraint_error =
        computeLoopError(model, data, *loops_, result.q).lpNorm<Eigen::Infinity>();
    result.wall_time = std::chrono::duration<double>(Clock::now() - start).count();
    return result;
  }

  void Solver::polish(StabilityReport & report, const ForceModel * forces, Result & result)
  {
    const pinocchio::Model & model = model_;
    // The correction a rest in a basin needs is about residual / (smallest stiffness): allow ten
    // times that and no more, so that Newton cannot wander to another stationary point.
    double softest = 0.;
    for (Eigen::Index k = 0; k < report.eigenvalues.size(); ++k)
      if (report.eigenvalues[k] > report.tolerance)
      {
        softest = report.eigenvalues[k];
        break;
      }
    if (softest <= 0.)
      return;
    const double reach = 10. * result.residual / softest;

    Eigen::VectorXd q = result.q, q_next(model.nq);
    Eigen::VectorXd tau = staticForce(q, forces);
    double residual = tau.lpNorm<Eigen::Infinity>();
    int iterations = 0;
    for (; iterations < 10 && residual > 0.; ++iterations)
    {
      // Newton on the allowed motions (all of them without loops): K ds = -B^T tau, dq = B ds.
      const StabilityReport at = loops_ != nullptr ? assess(q, forces) : StabilityReport();
      const Eigen::MatrixXd K =
        loops_ != nullptr ? at.stiffness : computeStiffnessMatrix(model, data, q, forces);
      // Least squares with a rank cut: neutral directions (K singular there) are left alone.
      Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(K);
      cod.setThreshold(
        std::max(report.tolerance / std::max(report.max_abs_eigenvalue, 1e-300), 1e-12));
      const Eigen::VectorXd dq =
        loops_ != nullptr ? Eigen::VectorXd(-at.basis * cod.solve(at.basis.transpose() * tau))
                          : Eigen::VectorXd(-cod.solve(tau));
      pinocchio::integrate(model, q, dq, q_next);
      if (loops_ != nullptr)
        projectOntoLoops(model, data, *loops_, q_next);
      const Eigen::VectorXd tau_next = staticForce(q_next, forces);
      const double residual_next = tau_next.lpNorm<Eigen::Infinity>();
      if (!(residual_next < residual))
        break;
      q.swap(q_next);
      tau = tau_next;
      residual = residual_next;
    }
    result.polish_iterations = iterations;
    if (iterations == 0)
      return;
    const double moved = pinocchio::difference(model, result.q, q).lpNorm<Eigen::Infinity>();
    const StabilityReport after = assess(q, forces);
    if (moved > reach || after.verdict != report.verdict)
      return;
    result.q = q;
    result.residual = residual;
    result.polished = true;
    report = after;
  }

} // namespace pinsettle
