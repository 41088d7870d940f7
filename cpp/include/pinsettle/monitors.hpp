//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_monitors_hpp__
#define __pinsettle_monitors_hpp__

#include "pinsettle/result.hpp"
#include "pinsettle/settings.hpp"
#include "pinsettle/stability.hpp"

#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

namespace pinsettle
{

  /// \brief Where a run stands, as the callback sees it.
  struct RunProgress
  {
    /// Steps taken so far.
    std::int64_t steps = 0;
    /// Simulated time (s).
    double sim_time = 0.;
    /// Kinetic energy of the last step (J, the real bodies).
    double kinetic_energy = 0.;
    /// Damping events so far.
    std::int64_t peaks = 0;
    /// Wall time since the run started (s).
    double wall_time = 0.;
    /// Computes the residual at the current configuration; set by the solver.
    std::function<double()> compute_residual;

    /// \brief Residual at the current configuration (N m or N, as Result::residual), computed
    /// when asked (a static force), NaN without a solver behind it.
    double residual() const
    {
      return compute_residual ? compute_residual() : std::numeric_limits<double>::quiet_NaN();
    }
  };

  /// \brief Called every Settings::check_every steps with the run's progress; returning true
  /// stops the run with Status::Aborted and keeps the current state.
  typedef std::function<bool(const RunProgress &)> AbortCallback;

  ///
  /// \brief The wall clock and the abort callback, polled every Settings::check_every steps.
  ///
  class RunClock
  {
  public:
    /// Starts the clock.
    RunClock();

    /// \brief Take the budget and the callback of a run (the clock keeps running).
    void configure(const Settings & settings, const AbortCallback & abort);

    /// \brief Whether step is one at which the clock and the callback are polled.
    bool isDue(std::int64_t step) const
    {
      return step > 0 && step % check_every_ == 0;
    }

    ///
    /// \brief Poll the clock, then the callback.
    /// \param[in,out] progress The run's progress, given to the callback (its wall_time is
    ///                 set here).
    /// \return Status::TimeLimit or Status::Aborted when the run must stop, else nothing.
    ///
    std::optional<Status> mustStop(RunProgress & progress) const;

    /// \brief Seconds since the clock started.
    double elapsed() const;

  private:
    typedef std::chrono::steady_clock Clock;
    Clock::time_point start_;
    std::int64_t check_every_ = 1;
    double max_time_ = 0.;
    bool check_clock_ = false;
    const AbortCallback * abort_ = nullptr;
  };

  ///
  /// \brief Divergence guard: watches each step for non-finite values or an energy explosion
  /// that no resolved motion makes, and keeps the last good state to roll back to.
  ///
  /// The good state is the start, then the state after each push and after each damping event
  /// whose stretch never grew the energy kBlowUpRatio-fold in one step (an explosion can pass a
  /// peak before it is caught). The solver halves its step at each roll-back.
  ///
  class DivergenceGuard
  {
  public:
    /// Kinetic energy ratio between consecutive steps, held for kBlowUpSteps steps in a row,
    /// that no resolved motion produces: with dt <= 2 / omega_max a physical instability grows
    /// the energy at most e^2 per step; the explicit integrator past its limit grows it faster.
    static constexpr double kBlowUpRatio = 10.;
    static constexpr int kBlowUpSteps = 10;
    /// Energies beyond this (J) are treated like non-finite values (they soon are).
    static constexpr double kHugeEnergy = 1e150;
    /// Roll-backs before the run is declared diverged.
    static constexpr int kMaxReductions = 30;

    /// \brief Start a run at the good state (q, v, time); sizes the memory of the state.
    void start(const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time);

    ///
    /// \brief Look at one step's values; call once per step, after the dynamics.
    ///
    /// \param[in] e_exact The exact kinetic energy (J).
    /// \param[in] e_simple The simplified energy.
    /// \param[in] ddq The joint acceleration (dim model.nv).
    /// \param[in] continued Whether the previous step belongs to the same undamped stretch.
    /// \return Whether the step blew up: roll back.
    ///
    bool isDiverging(double e_exact, double e_simple, const Eigen::VectorXd & ddq, bool continued);

    /// \brief Make (q, v, time) the good state (after a push).
    void keep(const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time);

    /// \brief Make (q, v, time) the good state unless the stretch that led to it grew
    /// suspiciously (after a damping event).
    void keepIfClean(const Eigen::VectorXd & q, const Eigen::VectorXd & v, double time);

    ///
    /// \brief Restore the good state.
    /// \return false once kMaxReductions roll-backs were made before this one (the state is
    ///         restored all the same): the run has diverged.
    ///
    bool rollBack(Eigen::VectorXd & q, Eigen::VectorXd & v, double & time);

    /// \brief Forget the growth seen in the interrupted stretch.
    void restart()
    {
      blow_up_ = 0;
      tainted_ = false;
    }

    /// \brief Roll-backs made.
    int reductions() const
    {
      return reductions_;
    }

  private:
    Eigen::VectorXd q_good_, v_good_;
    double time_good_ = 0., e_exact_prev_ = 0.;
    int blow_up_ = 0, reductions_ = 0;
    bool tainted_ = false;
  };

  ///
  /// \brief Runaway monitor (no equilibrium): the energy released by the potential since the
  /// last reset (kinetic energy gained plus energy taken out) and the net motion since then,
  /// sampled at doublings of the run length.
  ///
  /// When the energy released over each doubling of the run and the net motion both grow by
  /// kRunawayRatio or more, kRunawayDoublings doublings in a row, the potential falls without
  /// bound along the motion; a mechanism ringing in place stays put, and one settling in a well
  /// releases less and less. The release per doubling (not the total) is what sees a runaway in
  /// part of a mechanism: a free finger sliding off an arm that first released a lot in its
  /// own well (the total then grows too slowly for long).
  ///
  class RunawayMonitor
  {
  public:
    static constexpr double kRunawayRatio = 1.5;
    static constexpr int kRunawayDoublings = 8;
    /// Steps from a reset to the first sample: its own span, not the stopping window's (a
    /// shorter one would call a slow swing's first quarter a runaway sooner).
    static constexpr std::int64_t kFirstSample = 100;

    ///
    /// \brief Start a run: sizes the memory of the net motion.
    /// \param[in] nv Tangent dimension (model.nv).
    /// \param[in] first_sample Steps from a reset to the first sample (kFirstSample).
    /// \param[in] floor Energy (J) a doubling must release to count at all: round-off creep
    ///            along a neutral direction releases ever more of almost nothing.
    ///
    void start(Eigen::Index nv, std::int64_t first_sample, double floor = 0.);

    /// \brief Start counting again at step, with the kinetic energy e (J) there.
    void reset(std::int64_t step, double e);

    /// \brief Energy taken out of the run (J): by a damping event, or by an estimate that took
    /// added inertia away (StepController::estimate).
    void addRemoved(double e)
    {
      removed_ += e;
    }

    /// \brief A step's motion dq (dim model.nv, tangent, rad or m).
    void addMotion(const Eigen::VectorXd & dq)
    {
      drift_ += dq;
    }

    /// \brief Whether step is a sampling step.
    bool isDue(std::int64_t step) const
    {
      return step - reset_step_ == next_sample_;
    }

    ///
    /// \brief Take a sample; call when isDue(step).
    /// \param[in] e The kinetic energy now (J, the stiff modes' added inertia included).
    /// \return Whether both the energy released per doubling and the net motion grew
    ///         kRunawayDoublings times in a row: a runaway.
    ///
    bool sample(double e);

    /// \brief What the last sample saw: energy released (J), net motion (rad or m, max norm),
    /// steps since the reset.
    double released() const
    {
      return released_sample_;
    }
    double drift() const
    {
      return drift_sample_;
    }
    /// \brief Energy (J) a doubling must release to count at all (start's floor).
    double floor() const
    {
      return floor_;
    }
    /// \brief The net motion since the reset (dim model.nv, tangent, rad or m).
    const Eigen::VectorXd & motion() const
    {
      return drift_;
    }
    /// \brief The tangent coordinate (index in model.nv) that has moved furthest since the reset.
    Eigen::Index furthestCoordinate() const
    {
      Eigen::Index k = 0;
      if (drift_.size() > 0)
        drift_.cwiseAbs().maxCoeff(&k);
      return k;
    }
    std::int64_t stepsSinceReset(std::int64_t step) const
    {
      return step - reset_step_;
    }

  private:
    std::int64_t first_sample_ = 1, reset_step_ = 0, next_sample_ = 1;
    double e_reset_ = 0., removed_ = 0., released_sample_ = 0., increment_sample_ = 0.,
           drift_sample_ = 0., floor_ = 0.;
    int growing_ = 0;
    // Net motion since the reset in tangent coordinates (a continuous joint unwrapped).
    Eigen::VectorXd drift_;
  };

  ///
  /// \brief Rest check: when the energy signals call for a stability assessment, whether the
  /// assessed rest ends the run, and the push off an unstable one.
  ///
  /// The signals: quiet and not rising (the stopping rule); exact rest (a start on an
  /// equilibrium: a step from rest that moved nothing, or a whole window at zero energy); quiet but
  /// still rising, once a window (creeping away from a saddle a round-off off). A neutral rest ends
  /// the run, creeping or not: a round-off force along its neutral direction (a joint about the
  /// vertical) raises the energy forever without a peak. A stable rest ends it unless it was only
  /// creeping (it swings back: a peak comes), or creeping with q unchanged since the last
  /// assessment: steps below the resolution of q (a fixed step of 2e-4 s at 1e-13 rad/s) leave q
  /// where it is while a round-off force raises v for ever, and no swing back comes; an unstable
  /// one (a saddle, a maximum) is pushed along its most negative stiffness direction with a tiny
  /// energy, so that it falls away to where the mechanism would really stay.
  ///
  class RestCheck
  {
  public:
    ///
    /// \param[in] window Steps between two assessments of a creeping rest (Settings::ds, at
    ///            least model.nv: an assessment costs O(nv^3), a step O(nv)).
    /// \param[in] push_energy Energy of a push (unit of the energy signal).
    /// \param[in] measure The energy signal.
    /// \param[in] rest_energy_limit Most potential energy (J) a rest may have left to release
    ///            (computeRestEnergy) to end the run.
    ///
    void start(
      std::int64_t window, double push_energy, EnergyMeasure measure, double rest_energy_limit);

    /// \brief Whether the signals call for an assessment at step.
    bool isDue(bool quiet, bool not_rising, bool exact_rest, std::int64_t step);

    ///
    /// \brief Keep the assessment of q, made at step (moved in: its matrices are not copied).
    /// \param[in] rest_energy computeRestEnergy of the assessment (J); infinity for an unstable
    ///            one.
    ///
    void record(
      StabilityReport report, const Eigen::VectorXd & q, std::int64_t step, double rest_energy);

    /// \brief Whether the rest just assessed ends the run: stable or neutral, not merely
    /// creeping, and close enough to its rest (rest_energy_limit). A quiet run far from a rest
    /// (the step halved until nothing moves) goes on.
    bool accepts() const
    {
      const bool kind = report_.verdict == Stability::Neutral
                        || (report_.verdict == Stability::Stable && (!creeping_ || stalled_));
      return kind && rest_energy_ <= rest_energy_limit_;
    }

    /// \brief computeRestEnergy of the last assessment (J).
    double restEnergy() const
    {
      return rest_energy_;
    }

    /// \brief Whether the rest just assessed must be pushed off.
    bool isUnstable() const
    {
      return report_.verdict == Stability::Unstable;
    }

    ///
    /// \brief The push: v along the assessed softest direction, scaled to the push energy.
    /// \param[in] q The configuration assessed (dim model.nq).
    /// \param[out] v The joint velocity (dim model.nv).
    ///
    void push(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      Eigen::VectorXd & v) const;

    /// \brief The last assessment, and whether it was made at q.
    const StabilityReport & report() const
    {
      return report_;
    }
    bool isAssessed(const Eigen::VectorXd & q) const
    {
      return report_.verdict != Stability::Unknown && report_q_ == q;
    }

    /// \brief Hand the last assessment over at the end of a run (the check keeps none).
    StabilityReport takeReport()
    {
      report_q_.resize(0);
      return std::move(report_);
    }

  private:
    std::int64_t window_ = 1, last_assessed_ = 0;
    double push_energy_ = 0., rest_energy_ = 0., rest_energy_limit_ = 0.;
    EnergyMeasure measure_ = EnergyMeasure::Exact;
    bool creeping_ = false, stalled_ = false;
    StabilityReport report_;
    Eigen::VectorXd report_q_;
  };

  ///
  /// \brief The optional trace: energy samples every trace_every steps in bounded memory (when
  /// full, every other sample is dropped and the stride doubles) and every velocity event.
  ///
  class TraceRecorder
  {
  public:
    /// \brief Start a run's trace (Settings::trace_every 0: nothing is recorded).
    void start(const Settings & settings);

    /// \brief Record a sample at step when it falls on the stride.
    void sample(
      std::int64_t step, double time, double e_exact, double e_simple, const Eigen::VectorXd & q);

    /// \brief Record a velocity event (when tracing); joint for an impact.
    void event(std::int64_t step, double time, EventKind kind, pinocchio::JointIndex joint = 0)
    {
      if (tracing_)
        events_.push_back(TraceEvent{step, time, kind, joint});
    }

    /// \brief Whether this run is traced.
    bool isTracing() const
    {
      return tracing_;
    }

    /// \brief Hand the trace over to the result.
    void finish(Trace & trace);

  private:
    bool tracing_ = false, configurations_ = false;
    std::int64_t stride_ = 0;
    std::size_t capacity_ = 0;
    std::vector<TraceSample> samples_;
    std::vector<TraceEvent> events_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_monitors_hpp__
