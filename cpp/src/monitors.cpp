//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/monitors.hpp"
#include "pinsettle/energy.hpp"

#include <algorithm>
#include <cmath>

namespace pinsettle
{

  RunClock::RunClock()
  : start_(Clock::now())
  {
  }

  void RunClock::configure(const Settings & settings, const AbortCallback & abort)
  {
    check_every_ = settings.check_every;
    max_time_ = settings.max_time;
    check_clock_ = std::isfinite(settings.max_time);
    abort_ = abort ? &abort : nullptr;
  }

  std::optional<Status> RunClock::mustStop(RunProgress & progress) const
  {
    progress.wall_time = elapsed();
    if (check_clock_ && progress.wall_time > max_time_)
      return Status::TimeLimit;
    if (abort_ != nullptr && (*abort_)(progress))
      return Status::Aborted;
    return std::nullopt;
  }

  double RunClock::elapsed() const
  {
    return std::chrono::duration<double>(Clock::now() - start_).count();
  }

  void DivergenceGuard::start(const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time)
  {
    keep(q, v, time);
    e_exact_prev_ = 0.;
    blow_up_ = 0;
    reductions_ = 0;
    tainted_ = false;
  }

  bool DivergenceGuard::isDiverging(
    double e_exact, double e_simple, const Eigen::VectorXd & ddq, bool continued)
  {
    blow_up_ =
      continued && e_exact_prev_ > 0. && e_exact > kBlowUpRatio * e_exact_prev_ ? blow_up_ + 1 : 0;
    tainted_ = tainted_ || blow_up_ > 0;
    e_exact_prev_ = e_exact;
    // A kinetic energy below zero is no state of a mechanism (every body's term is >= 0 for
    // the inertias the model check admits): the arithmetic of one blown past its range. go1
    // standing at a fixed step of 0.1 s grew 4 to 1e10-fold a step, nine steps in a row, then
    // read -2.6e53 J, was taken for quiet, assessed and pushed, and the push kept that state as
    // the one to roll back to.
    return !std::isfinite(e_exact) || !std::isfinite(e_simple) || e_exact > kHugeEnergy
           || e_exact < 0. || !ddq.allFinite() || blow_up_ >= kBlowUpSteps;
  }

  void DivergenceGuard::keep(const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time)
  {
    q_good_ = q;
    v_good_ = v;
    time_good_ = time;
  }

  void DivergenceGuard::keepIfClean(
    const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time)
  {
    if (!tainted_)
      keep(q, v, time);
  }

  bool DivergenceGuard::rollBack(Eigen::VectorXd & q, Eigen::VectorXd & v, double & time)
  {
    q = q_good_;
    v = v_good_;
    time = time_good_;
    if (reductions_ == kMaxReductions)
      return false;
    ++reductions_;
    return true;
  }

  void RunawayMonitor::start(Eigen::Index nv, std::int64_t first_sample, double floor)
  {
    first_sample_ = first_sample;
    floor_ = floor;
    drift_.setZero(nv);
    reset(0, 0.);
  }

  void RunawayMonitor::reset(std::int64_t step, double e)
  {
    reset_step_ = step;
    next_sample_ = first_sample_;
    e_reset_ = e;
    removed_ = 0.;
    released_sample_ = 0.;
    increment_sample_ = 0.;
    drift_sample_ = 0.;
    growing_ = 0;
    drift_.setZero();
  }

  namespace
  {
    // Net motion (rad or m) a runaway must have made before it is confirmed: a revolute joint
    // that falls without bound keeps turning, so a full turn at least; a long first fall into a
    // well (a slow pendulum whose step is set by a stiff spring, over 100,000 steps) grows its
    // release per doubling for as long as it falls, but never travels that far.
    constexpr double kMinTravel = 2. * 3.14159265358979323846;
  } // namespace

  bool RunawayMonitor::sample(double e)
  {
    const double released = e - e_reset_ + removed_;
    const double increment = released - released_sample_;
    const double drift = drift_.lpNorm<Eigen::Infinity>();
    growing_ = increment > floor_ && increment_sample_ > 0.
                   && increment >= kRunawayRatio * increment_sample_ && drift_sample_ > 0.
                   && drift >= kRunawayRatio * drift_sample_
                 ? growing_ + 1
                 : 0;
    released_sample_ = released;
    increment_sample_ = increment;
    drift_sample_ = drift;
    next_sample_ *= 2;
    return growing_ >= kRunawayDoublings && drift >= kMinTravel;
  }

  void RestCheck::start(
    std::int64_t window, double push_energy, EnergyMeasure measure, double rest_energy_limit)
  {
    window_ = window;
    push_energy_ = push_energy;
    measure_ = measure;
    rest_energy_limit_ = rest_energy_limit;
    rest_energy_ = 0.;
    last_assessed_ = 0;
    creeping_ = stalled_ = false;
    report_ = StabilityReport();
    report_q_.resize(0);
  }

  bool RestCheck::isDue(bool quiet, bool not_rising, bool exact_rest, std::int64_t step)
  {
    creeping_ = quiet && !not_rising && step - last_assessed_ >= window_;
    return (quiet && not_rising) || exact_rest || creeping_;
  }

  void RestCheck::record(
    StabilityReport report, const Eigen::VectorXd & q, std::int64_t step, double rest_energy)
  {
    stalled_ = creeping_ && report_q_.size() == q.size() && report_q_ == q;
    rest_energy_ = rest_energy;
    report_ = std::move(report);
    report_q_ = q;
    last_assessed_ = step;
  }

  void RestCheck::push(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    Eigen::VectorXd & v) const
  {
    v = report_.softest_direction;
    const std::pair<double, double> unit = computeKineticEnergies(model, data, q, v);
    const double e_unit = measure_ == EnergyMeasure::Exact ? unit.first : unit.second;
    v *= e_unit > 0. ? std::sqrt(push_energy_ / e_unit) : 0.;
  }

  void TraceRecorder::start(const Settings & settings)
  {
    tracing_ = settings.trace_every > 0;
    configurations_ = settings.trace_configurations;
    stride_ = settings.trace_every;
    capacity_ = static_cast<std::size_t>(settings.trace_capacity);
    samples_.clear();
    events_.clear();
    if (tracing_) // never more samples than the run can record
      samples_.reserve(
        static_cast<std::size_t>(
          std::min(settings.trace_capacity, settings.max_steps / stride_ + 1)));
  }

  void TraceRecorder::sample(
    std::int64_t step, double time, double e_exact, double e_simple, const Eigen::VectorXd & q)
  {
    if (!tracing_ || step % stride_ != 0)
      return;
    if (samples_.size() == capacity_)
    {
      // Keep every other sample, so that the full trace covers the run at twice the stride.
      std::size_t kept = 0;
      for (std::size_t k = 0; k < samples_.size(); k += 2)
        samples_[kept++] = samples_[k];
      samples_.resize(kept);
      stride_ *= 2;
    }
    if (step % stride_ == 0)
      samples_.push_back(
        TraceSample{step, time, e_exact, e_simple, configurations_ ? q : Eigen::VectorXd()});
  }

  void TraceRecorder::finish(Trace & trace)
  {
    trace.samples = std::move(samples_);
    trace.events = std::move(events_);
    trace.stride = stride_;
    samples_.clear();
    events_.clear();
  }

} // namespace pinsettle
