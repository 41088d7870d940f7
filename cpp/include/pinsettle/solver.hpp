//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_solver_hpp__
#define __pinsettle_solver_hpp__

#include "pinsettle/constraint-set.hpp"
#include "pinsettle/damping.hpp"
#include "pinsettle/forces.hpp"
#include "pinsettle/loops.hpp"
#include "pinsettle/monitors.hpp"
#include "pinsettle/result.hpp"
#include "pinsettle/settings.hpp"
#include "pinsettle/stability.hpp"
#include "pinsettle/statics.hpp"
#include "pinsettle/step-control.hpp"
#include "pinsettle/stops.hpp"

#include <limits>
#include <memory>
#include <optional>
#include <string>

namespace pinsettle
{

  ///
  /// \brief Check a configuration given by a user.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] name How the caller calls it in error messages ("q0").
  /// \throws std::invalid_argument on a wrong size, a non-finite entry or a quaternion whose norm
  ///         differs from 1 by more than 1e-6 (the joint is named).
  ///
  void checkConfiguration(
    const pinocchio::Model & model, const Eigen::VectorXd & q, const char * name = "q0");

  ///
  /// \brief Check a joint velocity given by a user.
  ///
  /// \param[in] v The joint velocity (dim model.nv).
  /// \param[in] name How the caller calls it in error messages ("v0").
  /// \throws std::invalid_argument on a wrong size or a non-finite entry (the index is named).
  ///
  void checkVelocity(
    const pinocchio::Model & model, const Eigen::VectorXd & v, const char * name = "v0");

  ///
  /// \brief Check that the model can move at q: forward dynamics (pinocchio::aba) is finite,
  /// i.e. the joint space inertia matrix M(q) is invertible.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \throws std::invalid_argument when it is not: a joint moves no mass (a floating base on a
  ///         URDF root link without inertia, a joint whose child has no inertial); the joints
  ///         that make up the massless motion (eigenvector of M's smallest eigenvalue) are named.
  ///
  void checkMassMatrix(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q);

  ///
  /// \brief Why the mechanism can have no rest because a root joint translates freely: a free
  /// flyer, planar, translation or prismatic joint at the root that nothing ties to the world
  /// (no stop on it, no loop, coupling or element from its subtree to the world or another
  /// branch: ForceModel::tiesToWorld), under a net force along its translation. That force is
  /// the subtree's weight and loads, the same in every pose, so no motion of its joints can
  /// balance it: a falling humanoid, whatever its limbs do. Certain, unlike the runaway test,
  /// which must watch the motion.
  ///
  /// \param[in] q A configuration (dim model.nq).
  /// \return The reason, naming the joint and the force; empty where no root falls so.
  ///
  std::string explainFreeFall(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const LoopConstraints * loops,
    const JointStops * stops);

  /// \brief A Newton step that does not lower the residual is halved up to this many times
  /// before Newton gives up (Solver's polish and takeover).
  constexpr int kNewtonHalvings = 6;

  /// \brief A rest ends a run only with at most this many times Settings::max_e of potential
  /// energy left to release (computeRestEnergy): a quiet run that is not at a rest goes on.
  /// Measured with polish and the takeover off (docs/method.md, When is it a rest).
  constexpr double kRestEnergyFactor = 100.;

  /// \brief A runaway whose released energy exceeds this many times the work gravity and the
  /// applied efforts did on the way (plus the monitor's floor) was made by the integration: the
  /// step is rolled back and halved instead of the run ending with no equilibrium. A fall
  /// releases no more than that work (dampers, stops and contacts only take energy away). Steps
  /// too large for the mechanism released 71 (xarm7) to 3e6 (vehicle) times it, or the
  /// potential rose; a sphere rolling down a slope, a true runaway, 5.2 times (its contact
  /// impulses add energy as it spins).
  constexpr double kRunawayWorkFactor = 10.;

  ///
  /// \brief The most potential energy (J) a rest may have left to end a run:
  /// kRestEnergyFactor * settings.max_e, or for max_e = 0 round-off of the model's gravity
  /// scale (computeGravityScale). With the simplified measure max_e is read as J here too.
  ///
  double restEnergyLimit(const pinocchio::Model & model, const Settings & settings);

  ///
  /// \brief Kinetic-damping equilibrium solver.
  ///
  /// Simulates the mechanism with pinocchio::aba and semi-implicit Euler (pinocchio::integrate, so
  /// free-flyer and spherical joints stay on their manifold), and scales the joint velocity by
  /// Settings::kt at each detected peak of the kinetic energy, until the energy stays small.
  /// The solver owns its pinocchio::Data and a workspace sized for the model; the step loop does
  /// not allocate. The model must outlive the solver.
  ///
  /// Each concern of the loop is a part with its own state: the peak rule (PeakDetector), the
  /// stopping rule (StoppingWindow), the time step (StepController), the divergence guard
  /// (DivergenceGuard), the no-equilibrium test (RunawayMonitor), the stability check at rest
  /// (RestCheck), the trace (TraceRecorder) and the clock (RunClock).
  ///
  /// What restricts the motion (loop closures, joint stops) is one ConstraintSet: the loop asks
  /// it for the static force, residual and stability of a rest, the dynamics of a step and the
  /// impacts and projections after it, and never which kinds are present. With joint stops
  /// (JointStops) the start is moved into their ranges, a joint resting on a stop is held there
  /// while its stop pushes (StopHold), a joint that crosses a stop is put on it with its velocity
  /// into the stop removed (an inelastic impact), and the residual and the stability verdict are
  /// those of a rest against stops. With loop closures (LoopConstraints) each step runs
  /// Pinocchio's constrained forward dynamics (pinocchio::constraintDynamics) instead of aba,
  /// then projects q onto the loops (Gauss-Newton to 1e-13) and the velocity onto the motions
  /// they allow. Without constraints none of this runs.
  ///
  class Solver
  {
  public:
    ///
    /// \param[in] model The mechanism's tree.
    /// \param[in] loops Loop closures of the tree (they must outlive the solver), or nullptr.
    /// \param[in] stops Joint stops (they must outlive the solver), or nullptr.
    /// \param[in] contacts Ground contacts (they must outlive the solver), or nullptr.
    /// \throws std::invalid_argument when loops or stops were made for another model, or when
    ///         both are given (not supported yet).
    ///
    explicit Solver(
      const pinocchio::Model & model,
      const LoopConstraints * loops = nullptr,
      const JointStops * stops = nullptr,
      const GroundContacts * contacts = nullptr);
    ~Solver();

    ///
    /// \brief Settle the mechanism from rest at q0.
    ///
    /// \param[in] q0 The start configuration (dim model.nq).
    /// \param[in] settings Solver settings, checked with checkSettings.
    /// \param[in] forces Applied efforts, or nullptr for gravity alone.
    /// \param[in] abort Optional callback polled every settings.check_every steps.
    /// \throws std::invalid_argument on bad settings or a bad q0, or when the loops cannot be
    ///         assembled from q0 or leave no degree of freedom.
    ///
    Result solve(
      const Eigen::VectorXd & q0,
      const Settings & settings = Settings(),
      const ForceModel * forces = nullptr,
      const AbortCallback & abort = AbortCallback());

    ///
    /// \brief Settle the mechanism from the state (q0, v0).
    ///
    /// \param[in] v0 The start joint velocity (dim model.nv, finite).
    ///
    Result solve(
      const Eigen::VectorXd & q0,
      const Eigen::VectorXd & v0,
      const Settings & settings,
      const ForceModel * forces = nullptr,
      const AbortCallback & abort = AbortCallback());

    const pinocchio::Model & model() const
    {
      return model_;
    }

    /// \brief A rest Newton's method found (settleByNewton, polishRest).
    struct NewtonRest
    {
      Eigen::VectorXd q;                        ///< The rest (dim model.nq).
      double residual = 0.;                     ///< Its residual (N m or N, as Result::residual).
      double residual_from = 0.;                ///< The residual where Newton started.
      int iterations = 0;                       ///< Newton iterations taken (0: q kept as it was).
      Stability stability = Stability::Unknown; ///< The verdict at q.
    };

    ///
    /// \brief Newton's guarded takeover, as a run tries it at a damping event
    /// (Settings::newton_takeover), from where another method's run stands: a viscous or FIRE
    /// relaxation, or a user's own integrator, finishing with the same Newton as ours. Newton
    /// starts at q; its answer is taken only if it reaches round-off within its reach (0.1 rad
    /// or m, and ten times the residual over the softest stiffness), the rest is of the same
    /// kind as at q, which must not be unstable, and no force is left along a neutral direction
    /// (restEnergyLimit). The velocity is not looked at: a state far from rest just fails.
    ///
    /// \param[in] q Where the method stands (dim model.nq, normalised).
    /// \param[in] settings The solve's settings (max_e sets the neutral directions' limit).
    /// \param[in] forces Applied efforts, or nullptr for gravity alone.
    /// \return The rest, or std::nullopt where the method must go on.
    /// \throws std::invalid_argument on a bad q; std::logic_error on a solver with constraints
    ///         (their state belongs to a run).
    ///
    std::optional<NewtonRest> settleByNewton(
      const Eigen::VectorXd & q, const Settings & settings, const ForceModel * forces = nullptr);

    ///
    /// \brief Newton's polish of a rest another method converged to (Settings::polish): Newton
    /// steps from q, kept only if they stay within the reach of the rest (ten times the residual
    /// over its softest stiffness) and the rest stays of the same kind; else q is returned.
    ///
    /// \param[in] q The rest (dim model.nq, normalised).
    /// \param[in] forces Applied efforts, or nullptr for gravity alone.
    /// \throws As settleByNewton.
    ///
    NewtonRest polishRest(const Eigen::VectorXd & q, const ForceModel * forces = nullptr);

    /// Scratch of the last solve: kinematics of the last ABA call.
    pinocchio::Data data;

  private:
    /// The energies of one step, from the body velocities of its dynamics.
    struct StepEnergies
    {
      double exact;      // J, the real bodies
      double simplified; // sum |v|^2 + |w|^2
      double added;      // J, the scaled stiff modes' added inertia
      double signal;     // what the peak and stopping rules watch
    };

    // The steps of a run, in the order the loop takes them.
    void start(
      const Eigen::VectorXd & q0,
      const Eigen::VectorXd & v0,
      const Settings & settings,
      const ForceModel * forces,
      Result & result);
    // Whether nothing holds the mechanism against its weight (explainFreeFall): the reason and
    // the trace's one sample set in result.
    bool isFallingFreely(Result & result);
    // The step loop from the start to its end: the status it ends with (one exit).
    Status runLoop(RunClock & clock, const AbortCallback & abort, Result & result);
    // One pass of the loop at state_.step: the dynamics evaluated and, as the parts decide, a roll
    // back, a push off an unstable rest, a damping event or a step; the status when it ends the
    // run. energy: the exact kinetic energy of the pass (for the progress).
    std::optional<Status> takeStep(Result & result, double & energy);
    void reestimateStep();
    StepEnergies evaluateDynamics();
    // The constrained dynamics at the current state, on model or a copy of it.
    void computeAcceleration(const pinocchio::Model & model);
    // The acceleration the step integrates: with the scaled stiff modes' inertia and the joints
    // resting on their stops held (StopHold).
    void correctAcceleration();
    void restartStretch();
    bool rollBack(Result & result);
    // A runaway the monitor confirmed, and whether the energy it released was released by the
    // potential (a fall) or made by the integration (a time step too large: the work of gravity
    // and the applied efforts falls short of it).
    enum class Runaway
    {
      None,
      Fall,
      Integration
    };
    Runaway checkRunaway(const StepEnergies & e, Result & result);
    bool isMadeByIntegration();
    void resetRunaway(double e);
    bool isAssessedAtRest(const StepEnergies & e);
    void pushOff(Result & result);
    void damp(const StepEnergies & e, Result & result);
    // With backtracking: the configurations of the last two samples, and the move back to the
    // peak between them (false: not moved, the exact energy was still rising).
    void keepConfiguration(double exact);
    bool backtrackToPeak(double e, double exact);
    bool integrate();
    double residualOf(const Eigen::VectorXd & q, const Eigen::VectorXd & tau);
    void finish(Status status, Result & result);
    void measureProgress(double energy, const Result & result, RunProgress & progress);
    double progressResidual();

    // Whether the polish is at round-off after a Newton step of |dq|_inf = step (rad or m) that
    // followed one of last_step (0 for the first), at q.
    static bool isAtRoundOff(double step, double last_step, const Eigen::VectorXd & q);
    // Below this (times max(1, |q|_inf)) a Newton step moves q by its round-off only.
    static constexpr double kRoundOffStep = 1e-15;

    // Newton iterations from q0 (static force tau0, residual0), the first on report's
    // stiffness: at most 10, until the residual stops falling, the step is at round-off or q
    // has moved more than max_move (|dq|_inf from q0) away.
    struct NewtonRun
    {
      Eigen::VectorXd q, tau;
      double residual;
      int iterations;
      bool at_round_off; // ended at round-off (or a zero residual), not by a stall or the count
    };
    // Whether a Newton step dq that did not lower run's residual ends the run at round-off: the
    // step small at the rate of the last (isAtRoundOff), the residual at most kHeldResidual of
    // the forces' scale (the static force tau0 where the run began, the weight's moment).
    bool isStalledAtRoundOff(
      const NewtonRun & run,
      const Eigen::VectorXd & dq,
      double last_step,
      const Eigen::VectorXd & tau0) const;
    // Newton's step on the motions here's basis spans (every motion without constraints):
    // K ds = -B^T tau, dq = B ds, by least squares with report's rank cut.
    Eigen::VectorXd newtonStep(
      const StabilityReport & here, const StabilityReport & report, const Eigen::VectorXd & tau);
    // The step dq from run.q moved back onto the constraints (into q_next, scratch) and taken
    // into run only if the constraints hold there and the residual falls.
    bool takeNewtonStep(
      NewtonRun & run,
      const Eigen::VectorXd & dq,
      const ForceModel * forces,
      Eigen::VectorXd & q_next);
    NewtonRun iterateNewton(
      const Eigen::VectorXd & q0,
      const Eigen::VectorXd & tau0,
      double residual0,
      const StabilityReport & report,
      const ForceModel * forces,
      double max_move = std::numeric_limits<double>::infinity());
    // How far (|dq|_inf) Newton may move from a rest of this report and residual and stay in
    // its basin; negative when the report has no positive stiffness to tell.
    static double newtonReach(const StabilityReport & report, double residual);

    // Newton steps from the converged result.q, whose static force is tau; keeps them only if
    // the rest stays of the same kind (report) and close, and then tau is that of the new q.
    void polish(
      StabilityReport & report, const ForceModel * forces, Eigen::VectorXd & tau, Result & result);

    // Settings::newton_takeover, at a damping event (not sooner than max(1, nv^2 / 4) steps
    // after the last try): Newton from q, kept and the run ended only if it gets to round-off
    // within the reach and the rest stays of the same kind.
    bool isSettledByNewton(Result & result);
    // The takeover from q (settleByNewton's rule): the Newton run, the rest's report and the
    // residual at q; std::nullopt where it is refused.
    struct Takeover
    {
      NewtonRun run;
      StabilityReport report;
      double residual_from;
      double energy; // computeRestEnergy of the rest
    };
    std::optional<Takeover> takeOver(
      const Eigen::VectorXd & q, const Settings & settings, const ForceModel * forces);
    // Public entries' checks: no constraints, a valid q.
    void checkNewtonEntry(const Eigen::VectorXd & q, const char * who) const;
    // The farthest (|dq|_inf, rad or m: a radian the length scale, as the step estimates' far
    // move) Newton may take a takeover from where the mechanism stands.
    static constexpr double kTakeoverReach = 0.1;
    // A held rest's residual relative to the static force (|tau|_inf): round-off.
    static constexpr double kHeldResidual = 1e-12;

    // Static force and stiffness report of the constrained mechanism (ConstraintSet).
    Eigen::VectorXd staticForce(const Eigen::VectorXd & q, const ForceModel * forces);
    StabilityReport assess(const Eigen::VectorXd & q, const ForceModel * forces);

    // The run in progress: its inputs and where it is. start() sets it whole, so that nothing
    // of a previous run is read in the next (a solver is reused across solves).
    struct RunState
    {
      const Settings * settings = nullptr;
      const ForceModel * forces = nullptr;
      bool use_fext = false;
      double kt = 0.; // lowered to 0 when partial damping cannot hold a runaway
      std::int64_t step = 0;
      double time = 0.;
      int impacts = 0; // steps in a row with a joint past a stop
      // The last step started and ended at rest on the same q: an exact rest, no window needed.
      bool stationary = false;
      // Newton's takeover: the step of its last try, and whether it ended the run.
      std::int64_t newton_tried_at = 0;
      bool settled_by_newton = false;
      const pinocchio::Model * locked = nullptr; // the model this step's dynamics ran on, if locked
      double exact_before = 0.; // the exact energy (with added inertia) one sample back
    };

    // Memory sized once for the model: the state (q, v) and the loop's scratch.
    struct Workspace
    {
      explicit Workspace(const pinocchio::Model & model);
      Eigen::VectorXd q, v, dq, q_next, tau;
      Eigen::VectorXd drift; // v, or from rest the acceleration, at the last rest assessment
      Eigen::VectorXd q_before, q_before2; // q one and two samples back (backtracking)
      Eigen::VectorXd q_runaway;           // q at the runaway monitor's last reset
      ForceVector fext;
    };

    const pinocchio::Model & model_;
    ConstraintSet constraints_;                      // loops and stops: the loop never asks which
    std::unique_ptr<pinocchio::Data> progress_data_; // made on the first progress report
    RunState state_;
    Workspace work_;

    // The parts of the loop, each with its own state.
    PeakDetector peaks_;
    StoppingWindow window_;
    StepController step_control_;
    DivergenceGuard guard_;
    RunawayMonitor runaway_;
    RestCheck rest_;
    TraceRecorder trace_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_solver_hpp__
