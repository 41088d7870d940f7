//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_result_hpp__
#define __pinsettle_result_hpp__

#include "pinsettle/contacts.hpp"
#include "pinsettle/stops.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace pinsettle
{

  /// \brief How a solve ended.
  enum class Status
  {
    /// The stopping rule held: energy not rising and the window sum <= max_e.
    Converged,
    /// Settings::max_steps steps were taken without convergence.
    MaxSteps,
    /// Settings::max_time seconds elapsed without convergence.
    TimeLimit,
    /// The abort callback asked to stop (Ctrl-C from Python); the state is the current one.
    Aborted,
    /// The integration blew up (non-finite values or explosive energy growth) and halving the
    /// step 30 times did not cure it; the state is the last good one.
    Diverged,
    /// The motion never settles: the potential energy decreases without bound along it (a disk
    /// under a constant torque, a free body falling); Result::reason says what was seen.
    NoEquilibrium
  };

  /// \brief snake_case name of a status: "converged", "max_steps", ...
  const char * toString(Status status);

  /// \brief One sample of the optional trace.
  struct TraceSample
  {
    /// Step index (number of ABA evaluations before this sample).
    std::int64_t step;
    /// Simulated time (s).
    double time;
    /// Exact kinetic energy (J).
    double energy;
    /// Simplified energy sum |v|^2 + |w|^2 (m^2/s^2 + rad^2/s^2).
    double simplified_energy;
    /// Configuration (dim model.nq) when Settings::trace_configurations is set, else empty.
    Eigen::VectorXd q;
  };

  /// \brief What the solver did to the velocity at a traced event.
  enum class EventKind
  {
    /// Energy peak: the velocity was scaled by Settings::kt.
    Damping,
    /// Rest on an unstable equilibrium: pushed along the most negative stiffness direction.
    Push,
    /// Divergence guard: back to the last good state with the step halved.
    Rollback,
    /// Joint stop: a joint crossed its stop and was put on it, its velocity into it removed.
    Impact
  };

  /// \brief A velocity change, recorded while tracing (Settings::trace_every > 0).
  struct TraceEvent
  {
    /// Step index at which it happened.
    std::int64_t step;
    /// Simulated time (s).
    double time;
    EventKind kind;
    /// The joint that hit its stop (EventKind::Impact), else 0.
    pinocchio::JointIndex joint = 0;
  };

  /// \brief snake_case name of an event kind: "damping", "push", "rollback", "impact".
  const char * toString(EventKind kind);

  ///
  /// \brief How a solve went: its statistics, its timings and the figures behind its verdict.
  ///
  struct Info
  {
    /// Steps taken (ABA evaluations).
    std::int64_t steps = 0;
    /// Detected energy peaks, i.e. damping events.
    std::int64_t peaks = 0;
    /// Pushes off an unstable rest: at rest on a saddle or a maximum the mechanism is pushed
    /// along the most negative stiffness direction, so that only a stable or neutral rest is
    /// reported converged.
    std::int64_t pushes = 0;
    /// Time step in force at the end (s): the automatic estimate, or Settings::dt, times
    /// 0.5^dt_reductions.
    double dt = 0.;
    /// Automatic step estimates made (computeTimeScale); 0 with a fixed step.
    int dt_estimates = 0;
    /// Roll-backs to the last good state with the step halved (divergence guard).
    int dt_reductions = 0;
    /// Most stiff modes scaled by one estimate (Settings::scale_stiff_modes); 0 when none.
    int scaled_modes = 0;
    /// Most joints given an added inertia by one estimate (Settings::scale_joint_inertia).
    int scaled_joints = 0;
    /// Degrees of freedom of the mechanism: model.nv less the independent loop equations.
    int mobility = 0;
    /// How far the start configuration moved to assemble the loops (max |difference|, rad or
    /// m); 0 without loops.
    double assembly_distance = 0.;
    /// Joints whose start was outside their stops, and how far each was moved onto the nearest
    /// stop (rad or m).
    std::vector<std::pair<pinocchio::JointIndex, double>> start_clamped;
    /// Residual before the Newton polish (N m or N): where the run stopped, or where Newton
    /// took over at a damping event (Settings::newton_takeover); equal to Result::residual when
    /// not polished.
    double residual_before_polish = 0.;
    /// Newton iterations of the polish (or of the takeover); whether its result was kept.
    int polish_iterations = 0;
    bool polished = false;
    /// Simulated time (s).
    double sim_time = 0.;
    /// Wall-clock time of the solve (s).
    double wall_time = 0.;
    /// Exact kinetic energy 1/2 v^T M(q) v of the final state (J).
    double kinetic_energy = 0.;
    /// Simplified energy sum |v|^2 + |w|^2 of the final state.
    double simplified_kinetic_energy = 0.;
    /// Smallest eigenvalue of the symmetric part of the stiffness matrix (N m/rad or N/m).
    double min_stiffness_eigenvalue = 0.;
    /// Stiffness eigenvalues within the tolerance of zero (free directions).
    int neutral_directions = 0;
  };

  ///
  /// \brief The states a solve recorded (Settings::trace_every > 0), and its events.
  ///
  struct Trace
  {
    /// Samples in step order; empty when not tracing.
    std::vector<TraceSample> samples;
    /// Recording stride in force at the end (grows when the trace was decimated).
    std::int64_t stride = 0;
    /// Every damping event and push, in step order, when tracing (not decimated).
    std::vector<TraceEvent> events;
  };

  ///
  /// \brief Outcome of a kinetic-damping solve: the answer, with how the solve went (info) and
  /// what it recorded (trace) apart.
  ///
  struct Result
  {
    /// Final configuration (dim model.nq).
    Eigen::VectorXd q;
    /// Final joint velocity (dim model.nv).
    Eigen::VectorXd v;
    Status status = Status::MaxSteps;
    /// Why the run ended short of convergence (no_equilibrium, diverged), else empty.
    std::string reason;
    /// max |rnea(q, 0, 0) - applied generalized forces| of the final configuration (N m or N);
    /// with loops, of its component along the motions they allow (computeStaticForce); with
    /// stops, the largest violation of the conditions of a rest against them
    /// (computeStopResidual).
    double residual = 0.;
    /// Stability of the final configuration (assessStability).
    Stability stability = Stability::Unknown;
    /// Largest loop constraint error of the final configuration (m or rad); 0 without loops.
    double constraint_error = 0.;
    /// Joints resting on a stop at the end, with the stops' reactions; empty without stops.
    std::vector<StopContact> stop_contacts;
    /// The ground contacts closed at the end (gap within kContactGapTolerance), with the forces
    /// that balance the rest; empty without contacts.
    std::vector<GroundContact> ground_contacts;
    Info info;
    Trace trace;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_result_hpp__
