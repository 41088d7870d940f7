//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/solver.hpp"
#include "pinsettle/energy.hpp"
#include "pinsettle/stability.hpp"

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <algorithm>
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

  Solver::Solver(const pinocchio::Model & model)
  : data(model)
  , model_(model)
  , q_(model.nq)
  , v_(model.nv)
  , v_prev_(model.nv)
  , dq_(model.nv)
  , q_next_(model.nq)
  , tau_(Eigen::VectorXd::Zero(model.nv))
  , fext_(model.joints.size(), pinocchio::Force::Zero())
  {
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
    if (forces != nullptr && forces->empty())
      forces = nullptr; // nothing to apply: step exactly like the bare core

    const pinocchio::Model & model = model_;
    const double dt = settings.dt, kt = settings.kt, err = settings.err;
    const double max_e = settings.max_e;
    const bool exact = settings.energy == EnergyMeasure::Exact;
    const bool use_fext = forces != nullptr && forces->hasExternalForces();
    const bool check_clock = std::isfinite(settings.max_time);
    const bool tracing = settings.trace_every > 0;

    Result result;
    q_ = q0;
    pinocchio::normalize(model, q_); // q0 is normalised within 1e-6; make it exact
    v_ = v0;
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
      }

      if (forces != nullptr)
      {
        tau_.setZero();
        if (use_fext)
          for (pinocchio::Force & f : fext_)
            f.setZero();
        forces->computeForces(model, data, q_, v_, tau_, fext_);
      }
      if (use_fext)
        pinocchio::aba(model, data, q_, v_, tau_, fext_);
      else
        pinocchio::aba(model, data, q_, v_, tau_);

      // Both measures every step, from the body velocities ABA just computed.
      const double e_exact = computeBodyKineticEnergy(model, data);
      const double e_simple = computeSimplifiedKineticEnergy(model, data);
      const double e = exact ? e_exact : e_simple;

      if (!std::isfinite(e_exact) || !std::isfinite(e_simple) || !data.ddq.allFinite())
      {
        status = Status::Diverged;
        ++step;
        break; // (q_, v_) is finite: it was checked when it was integrated
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
        report = assessStability(model, data, q_, forces);
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
          still = 0;
          fresh = 0;
          window_count = 0;
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
          const double back = (1. - x) * dt;
          dq_.noalias() = -back * v_;
          pinocchio::integrate(model, q_, dq_, q_next_);
          q_.swap(q_next_);
          time -= back;
        }
        v_ *= kt;
        fresh = 0;
        continue; // re-evaluate the dynamics at the damped state
      }
      e_prev2 = e_prev;
      e_prev = e;
      ++fresh;

      // Semi-implicit Euler on the configuration manifold.
      v_prev_ = v_;
      v_.noalias() += dt * data.ddq;
      dq_.noalias() = dt * v_;
      pinocchio::integrate(model, q_, dq_, q_next_);
      if (!q_next_.allFinite() || !v_.allFinite())
      {
        v_ = v_prev_; // q_ still holds the last finite configuration
        status = Status::Diverged;
        ++step;
        break;
      }
      q_.swap(q_next_);
      time += dt;
    }

    result.status = status;
    result.steps = step;
    result.sim_time = time;
    result.trace_stride = trace_stride;
    result.q = q_;
    result.v = v_;
    const std::pair<double, double> energies = computeKineticEnergies(model, data, q_, v_);
    result.kinetic_energy = energies.first;
    result.simplified_kinetic_energy = energies.second;
    result.residual = computeStaticResidual(model, data, q_, forces);
    if (report.verdict == Stability::Unknown || report_q_ != q_)
      report = assessStability(model, data, q_, forces);
    result.stability = report.verdict;
    result.min_stiffness_eigenvalue = report.min_eigenvalue;
    result.neutral_directions = report.neutral_directions;
    result.wall_time = std::chrono::duration<double>(Clock::now() - start).count();
    return result;
  }

} // namespace pinsettle
