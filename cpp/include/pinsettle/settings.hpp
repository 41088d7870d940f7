//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_settings_hpp__
#define __pinsettle_settings_hpp__

#include <cstdint>
#include <limits>
#include <string>

namespace pinsettle
{

  /// \brief Which kinetic-energy signal drives the peak detection.
  enum class EnergyMeasure
  {
    /// E = sum_i 1/2 m_i |v_i|^2 + 1/2 w_i^T I_i w_i (J), equal to 1/2 qdot^T M(q) qdot.
    Exact,
    /// E_s = sum_i |v_i|^2 + |w_i|^2 (m^2/s^2 + rad^2/s^2), masses and inertias dropped.
    Simplified
  };

  /// \brief Name of an energy measure: "exact" or "simplified".
  const char * toString(EnergyMeasure measure);

  /// \brief Parse "exact" or "simplified"; throws std::invalid_argument otherwise.
  EnergyMeasure energyMeasureFromString(const std::string & name);

  /// \brief A switch that may also be left to the solver's measured rule.
  enum class Toggle : std::uint8_t
  {
    Off,
    On,
    /// The rule the setting documents (effectiveJointInertia for scale_joint_inertia).
    Auto
  };

  /// Safety factor of the automatic step with backtracking and the exact energy: the largest
  /// that kept every basin of the bistable pendulum's releases (0.4 lost 4 of 540), well below
  /// 0.7, the largest at which every run of the library's scenes converged (docs/method.md,
  /// docs/robustness.md).
  constexpr double kDtSafetyBacktrack = 0.3;
  /// Otherwise. Without backtracking a peak is seen one step late and stopping dead there
  /// (kt = 0) overshoots: a pendulum swings for ever between two such overshoots at 0.4, and at
  /// 0.3 77 of the 540 releases ended in another basin (17 at 0.2). With the simplified energy
  /// (masses left out) the light parts' peaks stop the heavy ones: a chain of masses 1e4 to
  /// 1e-4 kg never settled at kt = 0 with 0.25 or 0.3.
  constexpr double kDtSafetyDefault = 0.2;
  /// \brief The measured growth of the automatic step between damping events with backtracking,
  /// the exact energy and stiff-mode scaling (fewest steps over the robots, chains and scenes of
  /// benchmarks/dt_growth.py); without any of them it stays fixed. With the simplified energy
  /// the stress suite's chain of 1e4 to 1e-4 kg never settled at kt = 0 (light links' peaks
  /// stop the heavy ones, as above 0.2 of the limit); without stiff-mode scaling its chain of
  /// 1e-4 to 1e4 kg and 100 m to 1 mm links never settled from 2 up (at 1.5: 61,590 steps,
  /// fixed: 91,885).
  constexpr double kDtGrowthBacktrack = 2.5;
  /// \brief With scale_joint_inertia = Auto, the fewest degrees of freedom of a mechanism given
  /// the fictitious joint inertia. Measured (on over off, medians of 3; docs/method.md): chains
  /// released horizontal gain from 5 links (0.64 of the time) to 200 (0.036), and the talos
  /// (32) 0.84; below 20 the robots both gained (the Allegro hand 0.33, the SO-100 0.54) and lost
  /// (baxter, 19: 1.23; the xArm7 1.35; the finger_edu 1.18), and without stops the Panda's
  /// fingers slide off unseen by the runaway test (1e6 steps, against 51,201 without it).
  constexpr int kJointInertiaMinDofs = 20;

  ///
  /// \brief Inputs of the kinetic-damping solver. The solver only reads them.
  ///
  struct Settings
  {
    /// Time step of the semi-implicit Euler integration (s): > 0 for a fixed step, 0 (the
    /// default) for the automatic step dt_safety * TimeScale::critical_step, estimated at the
    /// start and again whenever the state has moved far (computeTimeScale).
    double dt = 0.;
    /// Safety factor c of the automatic step, in (0, 1]: the fraction of the linearised
    /// stability limit used; 0 (the default) for the measured one, kDtSafetyBacktrack with
    /// backtrack and the exact energy, kDtSafetyDefault otherwise (effectiveDtSafety).
    double dt_safety = 0.;
    /// With the automatic step: the largest factor it grows to between two damping events
    /// (>= 1; 1 keeps it fixed), or 0 (the default) for the measured one, kDtGrowthBacktrack
    /// with backtrack, the exact energy and scale_stiff_modes, 1 otherwise (effectiveDtGrowth).
    /// From each damping event, push or roll-back the step starts at the estimate and grows by
    /// StepController::kStepGrowthRate per step, never past the stability limit.
    double dt_growth = 0.;
    /// With the automatic step: give modes far stiffer than the rest (kStiffGap, kStiffSpread)
    /// a larger effective mass, so that the step follows the slow modes (computeTimeScale). The
    /// equilibria are unchanged; only the stiff modes' motion is slowed. Applied only where the
    /// longer step pays for the costlier one (kStiffCostBase, kStiffCostScale).
    bool scale_stiff_modes = true;
    /// With the automatic step and the exact energy, on a tree (no loops): give each joint a
    /// fictitious inertia (added to model.armature) that brings its own rate down towards the
    /// slowest joint's, re-chosen at each step estimate (computeJointInertia). The equilibria
    /// and their stability do not depend on the masses; the step follows the slow motion
    /// instead of the fastest joint's. Result::scaled_joints says how many were given one.
    /// Auto (the default): on mechanisms of kJointInertiaMinDofs degrees of freedom or more
    /// without ground contacts (effectiveJointInertia).
    Toggle scale_joint_inertia = Toggle::Auto;
    /// Velocity scale applied at each detected energy peak, in [0, 1). 0 (the default, the
    /// fewest steps measured: docs/benchmarks.md) stops the mechanism dead at each peak.
    double kt = 0.;
    /// Relative peak threshold: the middle of three samples is a peak when it exceeds both
    /// neighbours by more than err times its own value (dimensionless, >= 0). Relative so that
    /// peaks keep being detected when the energy has fallen by many orders of magnitude.
    double err = 1e-12;
    /// Length of the stopping window (steps), >= 1. 10 (the default, measured: docs/method.md,
    /// When to stop) took fewer steps than 100 on every measured run; 5 and 3 took a few percent
    /// fewer still but lost basins without backtracking. Every rest it finds is assessed and
    /// polished before it is reported.
    std::int64_t ds = 10;
    /// Stopping bound on the sum of the last ds energy samples, in the unit of the chosen
    /// energy measure (J for exact), >= 0. 1e-6 (the default, measured: docs/method.md, When to
    /// stop) leaves the rest's last digits to the polish and took the fewest steps of the bounds
    /// with which every polish reached round-off; 1e-4 left two rests unpolished. With
    /// polish = false, 1e-12 and ds = 100 give the run's own answer to about 1e-12 N m.
    double max_e = 1e-6;
    /// Largest number of steps (ABA evaluations), >= 1.
    std::int64_t max_steps = 1000000;
    /// Wall-clock budget (s), > 0; infinity means none.
    double max_time = std::numeric_limits<double>::infinity();
    /// Energy signal of the peak detector and the stopping rule.
    EnergyMeasure energy = EnergyMeasure::Exact;
    /// Move the configuration back to the parabola-interpolated peak before damping, along the
    /// path of the last two steps (only while the exact energy falls too). On by default: with
    /// it a coarser step stays safe and keeps the basins (kDtSafetyBacktrack).
    bool backtrack = true;
    /// Record a trace sample every trace_every steps; 0 disables the trace.
    std::int64_t trace_every = 0;
    /// Largest number of trace samples kept (>= 2); when full, every other sample is dropped
    /// and the recording stride doubles, so the whole run stays covered in bounded memory.
    std::int64_t trace_capacity = 10000;
    /// Also record the configuration in each trace sample (for playback); costs a copy of q
    /// per recorded sample.
    bool trace_configurations = false;
    /// After convergence, Newton steps on the static force with the stiffness matrix bring the
    /// residual to round-off; kept only if the rest stays stable (or neutral) and close. On by
    /// default: a few Newton steps take the default run's residual to 1e-10 of the force scale
    /// or below (docs/benchmarks.md).
    bool polish = true;
    /// With polish: at a damping event, try the polish's Newton from where the mechanism
    /// stands (at most once every max(1, nv^2 / 4) steps: a try costs O(nv^3), a step O(nv));
    /// when it gets to round-off within the polish's reach and 0.1 (rad or m) and the rest stays
    /// of the same kind (stable or neutral; never an unstable one), that rest ends the run.
    /// Measured over the scene library and the 21 robots: 0.81 of the time (geometric mean),
    /// the same verdicts and, at every strict minimum, the same rest (docs/method.md); a try
    /// whose Newton lands at round-off in one stride counts too (the UR5 48 to 23 steps). A
    /// rest with neutral directions ends where the first accepted try finds it. False: the run
    /// is the damping's own up to the polish after it.
    bool newton_takeover = true;
    /// The wall clock and the abort callback are checked every check_every steps (>= 1).
    std::int64_t check_every = 256;
  };

  ///
  /// \brief The safety factor the automatic step uses: settings.dt_safety, or for 0 the measured
  /// default, kDtSafetyBacktrack with backtrack and the exact energy, kDtSafetyDefault otherwise.
  ///
  inline double effectiveDtSafety(const Settings & settings)
  {
    if (settings.dt_safety != 0.)
      return settings.dt_safety;
    return settings.backtrack && settings.energy == EnergyMeasure::Exact ? kDtSafetyBacktrack
                                                                         : kDtSafetyDefault;
  }

  ///
  /// \brief The growth the automatic step uses: settings.dt_growth, or for 0 the measured
  /// default, kDtGrowthBacktrack with backtrack, the exact energy and stiff-mode scaling, 1
  /// otherwise.
  ///
  inline double effectiveDtGrowth(const Settings & settings)
  {
    if (settings.dt_growth != 0.)
      return settings.dt_growth;
    const bool measured =
      settings.backtrack && settings.energy == EnergyMeasure::Exact && settings.scale_stiff_modes;
    return measured ? kDtGrowthBacktrack : 1.;
  }

  ///
  /// \brief Whether the fictitious joint inertia is asked for on a mechanism of nv degrees of
  /// freedom (model.nv), with or without ground contacts: settings.scale_joint_inertia, or for
  /// Auto nv >= kJointInertiaMinDofs without contacts. Contacts' impulses are solved in the mass
  /// matrix the inertia changes, and their scenes lost with it (go1 standing 3.1 times the
  /// time, the MJCF ant 4.2, the vehicle 2.8). StepController applies it where the rest of its
  /// rule holds (the automatic step, the exact energy, no loops, more than one joint).
  ///
  inline bool effectiveJointInertia(const Settings & settings, int nv, bool contacts)
  {
    if (settings.scale_joint_inertia != Toggle::Auto)
      return settings.scale_joint_inertia == Toggle::On;
    return nv >= kJointInertiaMinDofs && !contacts;
  }

  ///
  /// \brief Check every field of the settings.
  /// \throws std::invalid_argument naming the field, the allowed range and the value given.
  ///
  void checkSettings(const Settings & settings);

} // namespace pinsettle

#endif // ifndef __pinsettle_settings_hpp__
