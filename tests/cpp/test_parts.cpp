//
// Boost.Test cases of the parts of the solver's loop, each on its own: the peak rule, the
// stopping window, the step controller and its integrator, the divergence guard, the runaway
// monitor, the rest check, the trace and the clock.
//

#define BOOST_TEST_MODULE pinsettle_parts
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

#include <Eigen/Eigenvalues>

#include <chrono>
#include <optional>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

namespace
{
  // A pendulum: a bob of mass m at distance l below a hinge about y (hanging down at q = 0).
  pinocchio::Model pendulum(double m = 1., double l = 1.)
  {
    pinocchio::Model model;
    const pinocchio::JointIndex j =
      model.addJoint(0, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "hinge");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(m, Eigen::Vector3d(0., 0., -l), Eigen::Matrix3d::Identity() * 1e-3));
    return model;
  }

  // A 10 kg pendulum carrying a 10 g slider on a 1e8 N/m spring: modes 1e4-fold apart in
  // frequency, so that the automatic step scales the slider's mode.
  pinocchio::Model pendulumWithStiffSlider()
  {
    pinocchio::Model model = pendulum(10., 1.);
    const pinocchio::JointIndex j =
      model.addJoint(1, pinocchio::JointModelPZ(), pinocchio::SE3::Identity(), "slider");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(0.01, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * 1e-6));
    return model;
  }
} // namespace

BOOST_AUTO_TEST_CASE(peak_detector_finds_the_maximum_one_sample_late)
{
  pinsettle::PeakDetector peaks(1e-12);
  const double samples[] = {1., 2., 3., 2.5, 1.};
  int found_at = -1;
  for (int k = 0; k < 5; ++k)
  {
    if (peaks.isPeak(samples[k]))
    {
      found_at = k;
      break;
    }
    peaks.record(samples[k]);
  }
  BOOST_CHECK_EQUAL(found_at, 3); // the maximum is sample 2, seen at sample 3
  BOOST_CHECK(peaks.isNotRising(2.5));
  BOOST_CHECK(!peaks.isNotRising(3.5));
  BOOST_CHECK(peaks.isNotRising(3.)); // flat: an orbit repeating exactly is not rising
}

BOOST_AUTO_TEST_CASE(peak_detector_ignores_bumps_below_err_and_needs_a_fresh_stretch)
{
  // A bump of 1e-13 relative is round-off for err = 1e-12.
  pinsettle::PeakDetector peaks(1e-12);
  peaks.record(1.);
  peaks.record(1. + 1e-13);
  BOOST_CHECK(!peaks.isPeak(1.));
  // The same bump is a peak with err = 0.
  pinsettle::PeakDetector exact(0.);
  exact.record(1.);
  exact.record(1. + 1e-13);
  BOOST_CHECK(exact.isPeak(1.));
  // After a restart two new samples are needed before a peak can be seen.
  exact.restart();
  BOOST_CHECK(!exact.hasPrevious());
  exact.record(5.);
  BOOST_CHECK(!exact.isPeak(1.));
  exact.record(6.);
  BOOST_CHECK(exact.isPeak(1.));
}

BOOST_AUTO_TEST_CASE(peak_detector_sees_the_flat_top_of_a_periodic_orbit)
{
  // Semi-implicit Euler on x'' = -omega^2 x from rest with h omega = 1 repeats every 6 steps;
  // the kinetic energy samples (the velocity of the step into each) are 0, E, E, 0, E, E, ...:
  // no sample exceeds both neighbours, the top is flat.
  pinsettle::PeakDetector peaks(1e-12);
  double x = 1., v = 0.;
  const double h = 0.1, omega = 10.;
  int found_at = -1;
  for (int k = 0; k < 6 && found_at < 0; ++k)
  {
    v -= h * omega * omega * x;
    x += h * v;
    const double e = 0.5 * v * v;
    if (peaks.isPeak(e))
      found_at = k;
    peaks.record(e);
  }
  BOOST_CHECK_EQUAL(found_at, 2); // the samples: E, E, 0
  // Rising to a plateau is not a peak; a plateau that stays is not either.
  pinsettle::PeakDetector plateau(1e-12);
  plateau.record(1.);
  plateau.record(2.);
  BOOST_CHECK(!plateau.isPeak(2.));
  plateau.record(2.);
  BOOST_CHECK(!plateau.isPeak(2.));
  BOOST_CHECK(plateau.isPeak(1.));
  BOOST_CHECK_CLOSE(plateau.stepsPastPeak(1.), 1.5, 1e-12); // the vertex halfway along the top
}

BOOST_AUTO_TEST_CASE(peak_detector_locates_the_vertex_of_a_parabola)
{
  // Samples of e(t) = 10 - (t - t0)^2 at t = 0, 1, 2: the vertex at t0; the last sample lies
  // 2 - t0 steps past it.
  for (const double t0 : {0.6, 1., 1.3})
  {
    pinsettle::PeakDetector peaks(0.);
    const auto e = [t0](double t) { return 10. - (t - t0) * (t - t0); };
    peaks.record(e(0.));
    peaks.record(e(1.));
    BOOST_REQUIRE(peaks.isPeak(e(2.)));
    BOOST_CHECK_CLOSE(peaks.stepsPastPeak(e(2.)), 2. - t0, 1e-10);
  }
}

BOOST_AUTO_TEST_CASE(stopping_window_is_quiet_only_when_full_and_small)
{
  pinsettle::StoppingWindow window(4, 1e-6);
  for (int k = 0; k < 3; ++k)
  {
    window.record(1e-8);
    BOOST_CHECK(!window.isQuiet(1e-8)); // not full yet
  }
  window.record(1e-8);
  BOOST_CHECK(window.isQuiet(1e-8)); // sum 4e-8
  // A large sample keeps it loud until it has left the window.
  window.record(1e-5);
  BOOST_CHECK(!window.isQuiet(1e-5));
  for (int k = 0; k < 3; ++k)
  {
    window.record(1e-8);
    BOOST_CHECK(!window.isQuiet(1e-8));
  }
  window.record(1e-8);
  BOOST_CHECK(window.isQuiet(1e-8));
  // The sum counts, not only the newest sample: four samples of 0.3e-6 sum past 1e-6.
  for (int k = 0; k < 4; ++k)
    window.record(0.3e-6);
  BOOST_CHECK(!window.isQuiet(0.3e-6));
  // A restart forgets the window.
  window.restart();
  window.record(0.);
  BOOST_CHECK(!window.isQuiet(0.));
}

BOOST_AUTO_TEST_CASE(stopping_window_sees_a_whole_window_of_exact_rest)
{
  pinsettle::StoppingWindow window(3, 1e-12);
  window.record(0.);
  window.record(0.);
  BOOST_CHECK(!window.isExactRest());
  window.record(0.);
  BOOST_CHECK(window.isExactRest());
  window.record(1e-300); // any energy at all breaks it
  BOOST_CHECK(!window.isExactRest());
}

BOOST_AUTO_TEST_CASE(semi_implicit_euler_updates_v_then_q)
{
  pinocchio::Model model;
  model.addJoint(0, pinocchio::JointModelSpherical(), pinocchio::SE3::Identity(), "ball");
  Eigen::VectorXd q = pinocchio::randomConfiguration(model), v(3), a(3), dq(3), q_next(4);
  v << 0.1, -0.2, 0.3;
  a << 1., 2., -3.;
  const Eigen::VectorXd v0 = v;
  pinsettle::integrateSemiImplicitEuler(model, q, v, a, 0.01, dq, q_next);
  BOOST_CHECK(v.isApprox(v0 + 0.01 * a, 1e-15));
  BOOST_CHECK(dq.isApprox(0.01 * v, 1e-15));
  BOOST_CHECK(q_next.isApprox(pinocchio::integrate(model, q, dq), 1e-15));
  BOOST_CHECK_SMALL(q_next.norm() - 1., 1e-14); // stays on the manifold
}

BOOST_AUTO_TEST_CASE(step_controller_fixed_step_is_the_setting)
{
  const pinocchio::Model model = pendulum();
  pinsettle::StepController control(model, nullptr);
  pinsettle::Settings settings;
  settings.dt = 2e-3;
  control.start(settings, nullptr);
  BOOST_CHECK(!control.isAutomatic());
  // A fixed step is never shortened, whatever the speed.
  BOOST_CHECK_EQUAL(
    control.nextStep(Eigen::VectorXd::Constant(1, 1e3), Eigen::VectorXd::Constant(1, 1e6)), 2e-3);
  BOOST_CHECK(!control.isEstimateDue(Eigen::VectorXd::Constant(1, 3.), 1000000));
  pinocchio::Data data(model);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(1), v = Eigen::VectorXd::Zero(1);
  BOOST_CHECK_EQUAL(control.halve(data, q, v, 0), 0.);
  BOOST_CHECK_EQUAL(control.dt(), 1e-3);
}

BOOST_AUTO_TEST_CASE(effective_dt_safety_follows_backtrack_unless_given)
{
  pinsettle::Settings settings; // dt_safety 0: the measured default
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtSafety(settings), 0.3);
  settings.backtrack = false;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtSafety(settings), 0.2);
  settings.backtrack = true;
  settings.energy = pinsettle::EnergyMeasure::Simplified;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtSafety(settings), 0.2);
  settings.energy = pinsettle::EnergyMeasure::Exact;
  settings.backtrack = false;
  settings.dt_safety = 0.25;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtSafety(settings), 0.25);
  settings.backtrack = true;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtSafety(settings), 0.25);
  // The automatic step of a pendulum without backtracking uses the smaller factor.
  const pinocchio::Model model = pendulum(2., 0.5);
  pinocchio::Data data(model);
  pinsettle::StepController with(model, nullptr), without(model, nullptr);
  pinsettle::Settings on, off;
  off.backtrack = false;
  with.start(on, nullptr);
  without.start(off, nullptr);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(1);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(1);
  with.estimate(data, q, v, 0);
  without.estimate(data, q, v, 0);
  BOOST_CHECK_CLOSE(with.dt(), 1.5 * without.dt(), 1e-12);
}

BOOST_AUTO_TEST_CASE(step_controller_automatic_step_of_a_pendulum)
{
  // Hanging at rest, the pendulum's only mode has omega^2 = m g l / I; the step is
  // dt_safety * 2 / omega.
  const double m = 2., l = 0.5, g = 9.81;
  const pinocchio::Model model = pendulum(m, l);
  pinocchio::Data data(model);
  pinsettle::StepController control(model, nullptr);
  pinsettle::Settings settings;
  control.start(settings, nullptr);
  BOOST_REQUIRE(control.isAutomatic());
  Eigen::VectorXd q = Eigen::VectorXd::Zero(1), v = Eigen::VectorXd::Zero(1);
  BOOST_CHECK_EQUAL(control.estimate(data, q, v, 0), 0.);
  const double inertia = m * l * l + 1e-3;
  const double omega = std::sqrt(m * g * l / inertia);
  const double c = pinsettle::effectiveDtSafety(settings); // the default: backtracking's
  BOOST_CHECK_EQUAL(c, pinsettle::kDtSafetyBacktrack);
  BOOST_CHECK_CLOSE(control.dt(), c * 2. / omega, 1e-6);
  BOOST_CHECK_EQUAL(control.estimates(), 1);
  // Slow motion takes the whole step; fast motion turns at most dt_safety per step.
  const Eigen::VectorXd none = Eigen::VectorXd::Zero(1);
  BOOST_CHECK_EQUAL(control.nextStep(Eigen::VectorXd::Constant(1, 1e-3), none), control.dt());
  BOOST_CHECK_CLOSE(control.nextStep(Eigen::VectorXd::Constant(1, -1e3), none), c / 1e3, 1e-12);
  BOOST_CHECK_EQUAL(control.lastStep(), c / 1e3);
  // From rest under a strong pull the kick counts: h^2 a = c, the move of the step.
  const double pull = 1e4;
  const double h = control.nextStep(none, Eigen::VectorXd::Constant(1, pull));
  BOOST_CHECK_CLOSE(h * h * pull, c, 1e-10);
  // Moving against the pull: the move h |v + h a| stays within c (the bound takes |v| + h |a|).
  for (const double v0 : {-3., 3., 30.})
  {
    const double hv =
      control.nextStep(Eigen::VectorXd::Constant(1, v0), Eigen::VectorXd::Constant(1, -pull));
    BOOST_CHECK_LE(hv * std::abs(v0 - hv * pull), c * (1. + 1e-12));
    BOOST_CHECK_CLOSE(hv * (std::abs(v0) + hv * pull), c, 1e-10);
  }
  // A new estimate is due once a window has passed and the pendulum moved beyond kFarMove.
  const Eigen::VectorXd near = Eigen::VectorXd::Constant(1, 0.05);
  const Eigen::VectorXd far = Eigen::VectorXd::Constant(1, 0.15);
  BOOST_CHECK(!control.isEstimateDue(far, settings.ds - 1));
  BOOST_CHECK(!control.isEstimateDue(near, settings.ds));
  BOOST_CHECK(control.isEstimateDue(far, settings.ds));
  // Halving: the re-estimate at the same place gives the same step, which the halving caps.
  const double before = control.dt();
  control.halve(data, q, v, 10);
  BOOST_CHECK_CLOSE(control.dt(), 0.5 * before, 1e-12);
  BOOST_CHECK_EQUAL(control.estimates(), 2);
}

BOOST_AUTO_TEST_CASE(step_controller_grows_between_damping_events)
{
  const pinocchio::Model model = pendulum(2., 0.5);
  pinocchio::Data data(model);
  const Eigen::VectorXd slow = Eigen::VectorXd::Constant(1, 1e-6), none = Eigen::VectorXd::Zero(1);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(1), v = Eigen::VectorXd::Zero(1);
  const auto stepsAfter = [&](pinsettle::StepController & control, int n) {
    double h = 0.;
    for (int i = 0; i < n; ++i)
      h = control.nextStep(slow, none);
    return h;
  };

  pinsettle::Settings settings; // dt_growth 0: the measured default
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtGrowth(settings), pinsettle::kDtGrowthBacktrack);
  pinsettle::StepController control(model, nullptr);
  control.start(settings, nullptr);
  control.estimate(data, q, v, 0);
  const double dt = control.dt();
  // 5 % a step from the estimate, up to dt_growth times it.
  BOOST_CHECK_EQUAL(control.nextStep(slow, none), dt);
  BOOST_CHECK_CLOSE(
    control.nextStep(slow, none), dt * pinsettle::StepController::kStepGrowthRate, 1e-12);
  BOOST_CHECK_CLOSE(stepsAfter(control, 100), pinsettle::kDtGrowthBacktrack * dt, 1e-12);
  BOOST_CHECK_EQUAL(control.dt(), dt); // the estimate itself is unchanged
  // A damping event starts it again; so does a halving, from the halved step.
  control.restartGrowth();
  BOOST_CHECK_EQUAL(control.nextStep(slow, none), dt);
  stepsAfter(control, 100);
  control.halve(data, q, v, 1);
  BOOST_CHECK_CLOSE(control.nextStep(slow, none), 0.5 * dt, 1e-12);
  // The turn bound still holds on the grown step.
  stepsAfter(control, 100);
  const double c = pinsettle::effectiveDtSafety(settings);
  BOOST_CHECK_CLOSE(control.nextStep(Eigen::VectorXd::Constant(1, 1e3), none), c / 1e3, 1e-12);

  // Never past the stability limit: dt_safety 0.5 grows at most twofold, to 2 / omega.
  settings.dt_safety = 0.5;
  settings.dt_growth = 3.;
  control.start(settings, nullptr);
  control.estimate(data, q, v, 0);
  BOOST_CHECK_CLOSE(stepsAfter(control, 100), 2. * control.dt(), 1e-12);
  BOOST_CHECK_CLOSE(2. * control.dt(), control.timeScale().critical_step, 1e-12);
  // 1 keeps it fixed, and so does the default without backtracking or with the simplified
  // energy.
  settings = pinsettle::Settings();
  settings.dt_growth = 1.;
  control.start(settings, nullptr);
  control.estimate(data, q, v, 0);
  BOOST_CHECK_EQUAL(stepsAfter(control, 100), control.dt());
  settings = pinsettle::Settings();
  settings.energy = pinsettle::EnergyMeasure::Simplified;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtGrowth(settings), 1.);
  settings.energy = pinsettle::EnergyMeasure::Exact;
  settings.backtrack = false;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtGrowth(settings), 1.);
  settings.backtrack = true;
  settings.scale_stiff_modes = false;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtGrowth(settings), 1.);
  settings.dt_growth = 1.5;
  BOOST_CHECK_EQUAL(pinsettle::effectiveDtGrowth(settings), 1.5);
  settings.dt_growth = 0.5;
  BOOST_CHECK_THROW(pinsettle::checkSettings(settings), std::invalid_argument);
}

// The message of a rejected setting names the field, what it must be and the value given.
std::string settingsError(const pinsettle::Settings & settings)
{
  try
  {
    pinsettle::checkSettings(settings);
  }
  catch (const std::invalid_argument & error)
  {
    return error.what();
  }
  return "";
}

BOOST_AUTO_TEST_CASE(a_rejected_setting_is_named_with_its_value)
{
  BOOST_CHECK_EQUAL(settingsError(pinsettle::Settings()), "");
  pinsettle::Settings settings;
  settings.kt = 1.5;
  BOOST_CHECK_EQUAL(settingsError(settings), "kt must be in [0, 1), got 1.5");
  settings = pinsettle::Settings();
  settings.max_steps = 0;
  BOOST_CHECK_EQUAL(settingsError(settings), "max_steps must be an integer >= 1, got 0");
  settings = pinsettle::Settings();
  settings.dt = -0.25;
  BOOST_CHECK_EQUAL(
    settingsError(settings),
    "dt must be a finite number > 0 (seconds), or 0 for 'auto', got -0.25");
  settings = pinsettle::Settings();
  settings.energy = static_cast<pinsettle::EnergyMeasure>(7);
  BOOST_CHECK_EQUAL(settingsError(settings), "energy must be \"exact\" or \"simplified\", got 7");
}

BOOST_AUTO_TEST_CASE(step_controller_scales_a_stiff_mode_consistently)
{
  const pinocchio::Model model = pendulumWithStiffSlider();
  pinocchio::Data data(model);
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(2, 1e8);
  pinsettle::StepController control(model, nullptr);
  pinsettle::Settings settings;
  control.start(settings, &springs);
  Eigen::VectorXd q(2), v(2);
  q << 0.3, 0.;
  v << 0.5, 0.;
  control.estimate(data, q, v, 0);
  BOOST_REQUIRE_EQUAL(control.stiffModes(), 1);
  BOOST_CHECK_EQUAL(control.scaledModes(), 1);
  // The same scaling, recomputed: M + W^T diag(d) W.
  const pinsettle::TimeScale scale = pinsettle::computeTimeScale(model, data, q, &springs, true);
  pinsettle::prebuilt::crba(model, data, q);
  Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
  const Eigen::MatrixXd scaled =
    M + scale.stiff_momenta.transpose() * scale.stiff_masses.asDiagonal() * scale.stiff_momenta;
  // Its step follows the slow mode: far longer than the unscaled limit 2 / omega_unscaled.
  BOOST_CHECK_GT(
    control.dt(), 100. * pinsettle::effectiveDtSafety(settings) * 2. / scale.omega_unscaled);
  // The added energy is 1/2 v^T (scaled - M) v.
  const Eigen::VectorXd w = Eigen::VectorXd::Random(2);
  BOOST_CHECK_CLOSE(control.addedEnergy(w), 0.5 * w.dot((scaled - M) * w), 1e-9);
  // The corrected acceleration a' solves (M + W^T D W) a' = M a.
  const Eigen::VectorXd a = Eigen::VectorXd::Random(2);
  // As in a step: the dynamics at q first (world convention), then its acceleration replaced.
  pinsettle::prebuilt::aba(
    control.dynamicsModel(), data, q, v, Eigen::VectorXd::Zero(2), pinocchio::Convention::WORLD);
  data.ddq = a;
  control.correctAcceleration(data);
  BOOST_CHECK((scaled * data.ddq).isApprox(M * a, 1e-9));
}

BOOST_AUTO_TEST_CASE(divergence_guard_catches_non_finite_and_explosive_steps)
{
  const Eigen::VectorXd finite = Eigen::VectorXd::Zero(2);
  Eigen::VectorXd nan = finite;
  nan[1] = std::numeric_limits<double>::quiet_NaN();
  pinsettle::DivergenceGuard guard;
  guard.start(finite, finite, 0.);
  BOOST_CHECK(!guard.isDiverging(1., 1., finite, false));
  BOOST_CHECK(guard.isDiverging(1., 1., nan, true));
  BOOST_CHECK(guard.isDiverging(std::numeric_limits<double>::infinity(), 1., finite, true));
  BOOST_CHECK(guard.isDiverging(1e151, 1., finite, true));

  // Energy growing 11-fold per step: caught at the kBlowUpSteps-th such step, not before.
  guard.start(finite, finite, 0.);
  double e = 1e-20;
  BOOST_CHECK(!guard.isDiverging(e, e, finite, false));
  int caught = 0;
  for (int k = 1; k <= 20 && caught == 0; ++k)
  {
    e *= 11.;
    if (guard.isDiverging(e, e, finite, true))
      caught = k;
  }
  BOOST_CHECK_EQUAL(caught, pinsettle::DivergenceGuard::kBlowUpSteps);
  // Growth of the same size in a new stretch (continued = false) does not count.
  guard.restart();
  BOOST_CHECK(!guard.isDiverging(1., 1., finite, false));
  BOOST_CHECK(!guard.isDiverging(20., 20., finite, false));
}

BOOST_AUTO_TEST_CASE(divergence_guard_rolls_back_to_the_last_clean_state)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(1), one = Eigen::VectorXd::Ones(1);
  pinsettle::DivergenceGuard guard;
  guard.start(zero, zero, 0.);
  guard.keepIfClean(one, one, 1.); // clean: kept
  BOOST_CHECK(!guard.isDiverging(1., 1., zero, false));
  BOOST_CHECK(!guard.isDiverging(20., 20., zero, true)); // one suspicious step taints
  guard.keepIfClean(2. * one, 2. * one, 2.);             // not kept
  Eigen::VectorXd q = 5. * one, v = 5. * one;
  double time = 5.;
  BOOST_CHECK(guard.rollBack(q, v, time));
  BOOST_CHECK_EQUAL(q[0], 1.);
  BOOST_CHECK_EQUAL(v[0], 1.);
  BOOST_CHECK_EQUAL(time, 1.);
  BOOST_CHECK_EQUAL(guard.reductions(), 1);
  // A push's state is always kept.
  guard.keep(3. * one, 3. * one, 3.);
  // The roll-backs run out after kMaxReductions; the state is restored all the same.
  for (int k = 1; k < pinsettle::DivergenceGuard::kMaxReductions; ++k)
    BOOST_CHECK(guard.rollBack(q, v, time));
  q.setZero();
  BOOST_CHECK(!guard.rollBack(q, v, time));
  BOOST_CHECK_EQUAL(q[0], 3.);
  BOOST_CHECK_EQUAL(guard.reductions(), pinsettle::DivergenceGuard::kMaxReductions);
}

BOOST_AUTO_TEST_CASE(runaway_monitor_sees_a_fall_without_bound_and_not_a_ringing)
{
  // A body falling at constant acceleration: released energy and distance grow 4-fold per
  // doubling of the run. Sampled at its own schedule (first after 10 steps).
  const double g = 9.81, dt = 1e-3;
  pinsettle::RunawayMonitor falling;
  falling.start(1, 10);
  Eigen::VectorXd dq(1);
  std::int64_t confirmed_at = -1;
  double x = 0., v = 0., x_confirmed = 0.;
  for (std::int64_t step = 0; step < (std::int64_t(10) << 14) && confirmed_at < 0; ++step)
  {
    if (falling.isDue(step) && falling.sample(0.5 * v * v))
    {
      confirmed_at = step;
      x_confirmed = x;
    }
    v += g * dt;
    dq[0] = v * dt;
    x += dq[0];
    falling.addMotion(dq);
  }
  // The first sample has nothing to compare with, then kRunawayDoublings growing ones.
  BOOST_CHECK_EQUAL(confirmed_at, std::int64_t(10) << pinsettle::RunawayMonitor::kRunawayDoublings);
  BOOST_CHECK_GT(falling.released(), 0.);
  BOOST_CHECK_CLOSE(falling.drift(), x_confirmed, 1e-9); // the motion up to the sample

  // A mechanism ringing in place releases and removes energy but goes nowhere.
  pinsettle::RunawayMonitor ringing;
  ringing.start(1, 10);
  bool runaway = false;
  for (std::int64_t step = 0; step < (std::int64_t(10) << 14); ++step)
  {
    const double phase = 0.01 * static_cast<double>(step);
    if (ringing.isDue(step))
      runaway = runaway || ringing.sample(0.5 * std::pow(std::sin(phase), 2));
    dq[0] = 0.01 * std::cos(phase);
    ringing.addMotion(dq);
    if (step % 300 == 0)
      ringing.addRemoved(1e-3);
  }
  BOOST_CHECK(!runaway);
  // A reset starts the schedule again from that step.
  ringing.reset(1000, 0.);
  BOOST_CHECK(!ringing.isDue(1000 + 9));
  BOOST_CHECK(ringing.isDue(1000 + 10));
}

BOOST_AUTO_TEST_CASE(rest_check_assesses_when_the_signals_say_so)
{
  pinsettle::RestCheck rest;
  rest.start(100, 1e-11, pinsettle::EnergyMeasure::Exact, 1e-4);
  BOOST_CHECK(!rest.isDue(false, true, false, 500));
  BOOST_CHECK(!rest.isDue(true, false, false, 50)); // quiet but rising: not a window yet
  BOOST_CHECK(rest.isDue(true, true, false, 50));   // the stopping rule
  BOOST_CHECK(rest.isDue(false, false, true, 50));  // a window of exact rest
  BOOST_CHECK(rest.isDue(true, false, false, 100)); // creeping, once a window
  pinsettle::StabilityReport stable;
  stable.verdict = pinsettle::Stability::Stable;
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(1);
  rest.record(stable, q, 100, 0.);
  BOOST_CHECK(!rest.accepts()); // a creeping stable rest is not accepted yet
  pinsettle::StabilityReport neutral;
  neutral.verdict = pinsettle::Stability::Neutral;
  rest.record(neutral, q, 100, 0.);
  BOOST_CHECK(rest.accepts()); // a creeping neutral one is: its energy may never peak
  pinsettle::StabilityReport unstable;
  unstable.verdict = pinsettle::Stability::Unstable;
  rest.record(unstable, q, 100, 0.);
  BOOST_CHECK(!rest.accepts());
  BOOST_CHECK(rest.isUnstable());
  rest.record(stable, q, 100, 0.);
  BOOST_CHECK(!rest.isDue(true, false, false, 150));
  BOOST_CHECK(rest.isDue(true, true, false, 150));
  rest.record(stable, q, 150, 0.);
  BOOST_CHECK(rest.accepts());
  BOOST_CHECK(rest.isAssessed(q));
  BOOST_CHECK(!rest.isAssessed(Eigen::VectorXd::Ones(1)));
  // Creeping at a stable rest a window later with q unchanged, to the bit: a stall below the
  // resolution of q, accepted; had q moved, the swing back is still to come.
  pinsettle::RestCheck stall;
  stall.start(100, 1e-11, pinsettle::EnergyMeasure::Exact, 1e-4);
  BOOST_CHECK(stall.isDue(true, false, false, 100));
  stall.record(stable, q, 100, 0.);
  BOOST_CHECK(!stall.accepts());
  BOOST_CHECK(stall.isDue(true, false, false, 200));
  stall.record(stable, Eigen::VectorXd::Constant(1, 1e-300), 200, 0.);
  BOOST_CHECK(!stall.accepts());
  BOOST_CHECK(stall.isDue(true, false, false, 300));
  stall.record(stable, Eigen::VectorXd::Constant(1, 1e-300), 300, 0.);
  BOOST_CHECK(stall.accepts());
  // The same stall with more potential energy left than the limit (1e-4 J): quiet because it
  // hardly moves, not a rest.
  stall.record(stable, Eigen::VectorXd::Constant(1, 1e-300), 400, 2e-4);
  BOOST_CHECK(!stall.accepts());
  rest.record(neutral, q, 400, 2e-4);
  BOOST_CHECK(!rest.accepts());
  rest.record(neutral, q, 400, 1e-4);
  BOOST_CHECK(rest.accepts());
}

BOOST_AUTO_TEST_CASE(rest_energy_is_the_potential_left_above_the_rest)
{
  // A pendulum of m = 2 kg, l = 0.5 m held at q: tau = m g l sin q, K = m g l cos q. The energy
  // left to its rest at 0 is m g l (1 - cos q), to second order 1/2 tau^2 / K.
  const double m = 2., l = 0.5, g = 9.81;
  const pinocchio::Model model = pendulum(m, l);
  pinocchio::Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 1e-3);
  const pinsettle::StabilityReport report = pinsettle::assessStability(model, data, q);
  const Eigen::VectorXd tau = pinsettle::computeStaticForce(model, data, q);
  BOOST_CHECK_CLOSE(
    pinsettle::computeRestEnergy(report, tau), m * g * l * (1. - std::cos(1e-3)), 1e-4);
  BOOST_CHECK_EQUAL(pinsettle::computeRestEnergy(report, Eigen::VectorXd::Zero(1)), 0.);
  // A force along a neutral direction (a vertical hinge turned by 1 N m) counts in full: its
  // stiffness is taken at the tolerance, so the energy is huge, not zero.
  pinsettle::StabilityReport flat =
    pinsettle::assessStiffness(Eigen::MatrixXd::Zero(1, 1), 1e-9, 1e-12);
  BOOST_CHECK(flat.verdict == pinsettle::Stability::Neutral);
  BOOST_CHECK_CLOSE(pinsettle::computeRestEnergy(flat, Eigen::VectorXd::Ones(1)), 0.5e12, 1e-9);
}

BOOST_AUTO_TEST_CASE(a_stiffness_of_round_off_is_neutral_under_the_model_floor)
{
  // Without a floor, eigenvalues of 8.9e-16 of either sign are read relative to the largest,
  // 8.9e-16 too: the negative one is 'unstable'. The model's own floor is far above them.
  const pinocchio::Model model = pendulum(2., 0.5);
  const double scale = pinsettle::computeGravityScale(model);
  BOOST_CHECK_CLOSE(scale, 2. * 9.81 * 0.5, 1e-12);
  Eigen::MatrixXd K(2, 2);
  K << -8.9e-16, 0., 0., 8.9e-16;
  BOOST_CHECK(pinsettle::assessStiffness(K, 1e-9).verdict == pinsettle::Stability::Unstable);
  const double floor = pinsettle::computeStiffnessFloor(model, false);
  BOOST_CHECK_CLOSE(floor, pinsettle::kStiffnessRoundOff * scale, 1e-12);
  const pinsettle::StabilityReport report = pinsettle::assessStiffness(K, 1e-9, floor);
  BOOST_CHECK(report.verdict == pinsettle::Stability::Neutral);
  BOOST_CHECK_EQUAL(report.neutral_directions, 2);
  // A real stiffness, however small against the weight (a link of 1e-4 kg and 1 mm under a
  // pendulum of 2 kg and 0.5 m: 1e-6 N m/rad), stays above the floor.
  K << 1e-6, 0., 0., 9.81;
  BOOST_CHECK(pinsettle::assessStiffness(K, 1e-9, floor).verdict == pinsettle::Stability::Stable);
}

BOOST_AUTO_TEST_CASE(rest_check_pushes_an_upright_pendulum_with_the_push_energy)
{
  const pinocchio::Model model = pendulum(2., 0.5);
  pinocchio::Data data(model);
  const Eigen::VectorXd upright = Eigen::VectorXd::Constant(1, M_PI);
  for (const pinsettle::EnergyMeasure measure :
       {pinsettle::EnergyMeasure::Exact, pinsettle::EnergyMeasure::Simplified})
  {
    pinsettle::RestCheck rest;
    rest.start(100, 1e-11, measure, 1e-4);
    BOOST_REQUIRE(rest.isDue(false, false, true, 100));
    rest.record(
      pinsettle::assessStability(model, data, upright), upright, 100,
      std::numeric_limits<double>::infinity());
    BOOST_REQUIRE(rest.isUnstable());
    BOOST_CHECK(!rest.accepts());
    Eigen::VectorXd v(1);
    rest.push(model, data, upright, v);
    const std::pair<double, double> e = pinsettle::computeKineticEnergies(model, data, upright, v);
    BOOST_CHECK_CLOSE(measure == pinsettle::EnergyMeasure::Exact ? e.first : e.second, 1e-11, 1e-9);
  }
}

BOOST_AUTO_TEST_CASE(trace_recorder_keeps_the_whole_run_in_bounded_memory)
{
  pinsettle::Settings settings;
  settings.trace_every = 1;
  settings.trace_capacity = 4;
  settings.trace_configurations = true;
  pinsettle::TraceRecorder trace;
  trace.start(settings);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(2, 0.5);
  for (std::int64_t step = 0; step < 13; ++step)
    trace.sample(step, 0.1 * static_cast<double>(step), 1., 2., q);
  trace.event(7, 0.7, pinsettle::EventKind::Push);
  pinsettle::Trace kept;
  trace.finish(kept);
  // Full at steps 0-3 (stride 1), then 0, 2 + 4, 6 (stride 2), then 0, 4 + 8, 12 (stride 4).
  BOOST_REQUIRE_EQUAL(kept.samples.size(), 4u);
  BOOST_CHECK_EQUAL(kept.stride, 4);
  for (std::size_t k = 0; k < 4; ++k)
  {
    BOOST_CHECK_EQUAL(kept.samples[k].step, static_cast<std::int64_t>(4 * k));
    BOOST_CHECK(kept.samples[k].q == q);
  }
  BOOST_REQUIRE_EQUAL(kept.events.size(), 1u);
  BOOST_CHECK(kept.events[0].kind == pinsettle::EventKind::Push);

  // Without tracing nothing is kept.
  settings.trace_every = 0;
  trace.start(settings);
  trace.sample(0, 0., 1., 2., q);
  trace.event(0, 0., pinsettle::EventKind::Damping);
  pinsettle::Trace none;
  trace.finish(none);
  BOOST_CHECK(none.samples.empty() && none.events.empty());
}

BOOST_AUTO_TEST_CASE(run_clock_stops_on_the_budget_and_on_the_callback)
{
  pinsettle::Settings settings;
  settings.check_every = 8;
  pinsettle::RunClock clock;
  clock.configure(settings, pinsettle::AbortCallback());
  BOOST_CHECK(!clock.isDue(0));
  BOOST_CHECK(!clock.isDue(7));
  BOOST_CHECK(clock.isDue(16));
  pinsettle::RunProgress progress;
  progress.steps = 16;
  BOOST_CHECK(!clock.mustStop(progress)); // no budget, no callback
  BOOST_CHECK_GE(progress.wall_time, 0.); // the clock read for the callback

  int calls = 0;
  std::int64_t steps_seen = 0;
  const pinsettle::AbortCallback abort = [&](const pinsettle::RunProgress & p) {
    steps_seen = p.steps;
    return ++calls >= 2;
  };
  clock.configure(settings, abort);
  BOOST_CHECK(!clock.mustStop(progress));
  const std::optional<pinsettle::Status> aborted = clock.mustStop(progress);
  BOOST_REQUIRE(aborted);
  BOOST_CHECK(*aborted == pinsettle::Status::Aborted);
  BOOST_CHECK_EQUAL(steps_seen, 16);

  settings.max_time = 1e-3;
  pinsettle::RunClock timed;
  timed.configure(settings, pinsettle::AbortCallback());
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::optional<pinsettle::Status> late = timed.mustStop(progress);
  BOOST_REQUIRE(late);
  BOOST_CHECK(*late == pinsettle::Status::TimeLimit);
  BOOST_CHECK_GE(timed.elapsed(), 5e-3);
}

BOOST_AUTO_TEST_CASE(free_fall_is_explained_only_where_nothing_holds_the_root)
{
  // A 3 kg box on a free flyer carrying a 1 kg pendulum: its weight, 39.24 N, is the net force
  // along the free flyer's translation in every pose.
  pinocchio::Model model;
  const pinocchio::JointIndex root =
    model.addJoint(0, pinocchio::JointModelFreeFlyer(), pinocchio::SE3::Identity(), "root");
  model.appendBodyToJoint(root, pinocchio::Inertia::FromBox(3., 0.2, 0.1, 0.1));
  const pinocchio::JointIndex arm =
    model.addJoint(root, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "arm");
  model.appendBodyToJoint(
    arm, pinocchio::Inertia(1., Eigen::Vector3d(0., 0., -0.5), Eigen::Matrix3d::Identity() * 1e-3));
  model.addFrame(
    pinocchio::Frame("box", root, 0, pinocchio::SE3::Identity(), pinocchio::FrameType::OP_FRAME));
  pinocchio::Data data(model);
  const Eigen::VectorXd q = pinocchio::randomConfiguration(
    model, -Eigen::VectorXd::Ones(model.nq), Eigen::VectorXd::Ones(model.nq));
  const std::string why = pinsettle::explainFreeFall(model, data, q, nullptr, nullptr, nullptr);
  BOOST_TEST_MESSAGE(why);
  BOOST_CHECK(why.find("'root'") != std::string::npos);
  BOOST_CHECK(why.find("39.24 N") != std::string::npos);
  // A joint spring on the pendulum is inside the subtree: still a fall.
  pinsettle::ForceElements inside(model);
  inside.addJointSpring(arm, 10., 0.);
  BOOST_CHECK(!pinsettle::explainFreeFall(model, data, q, &inside, nullptr, nullptr).empty());
  // A spring from the box to the world holds it: no certificate.
  pinsettle::ForceElements hung(model);
  hung.addPointSpring(
    0, Eigen::Vector3d::Zero(), model.getFrameId("box"), Eigen::Vector3d::Zero(), 100., 0.);
  BOOST_CHECK(pinsettle::explainFreeFall(model, data, q, &hung, nullptr, nullptr).empty());
  // A constant effort on the root's own coordinates may balance it: no certificate either.
  Eigen::VectorXd lift = Eigen::VectorXd::Zero(model.nv);
  lift[2] = 1.;
  const pinsettle::ConstantGeneralizedForce pushed(lift);
  BOOST_CHECK(pinsettle::explainFreeFall(model, data, q, &pushed, nullptr, nullptr).empty());
  // Without gravity nothing pulls: no fall.
  pinocchio::Model weightless = model;
  weightless.gravity.setZero();
  pinocchio::Data weightless_data(weightless);
  BOOST_CHECK(
    pinsettle::explainFreeFall(weightless, weightless_data, q, nullptr, nullptr, nullptr).empty());
}

BOOST_AUTO_TEST_CASE(a_prismatic_root_falls_unless_a_stop_holds_it)
{
  pinocchio::Model model;
  const pinocchio::JointIndex slide =
    model.addJoint(0, pinocchio::JointModelPZ(), pinocchio::SE3::Identity(), "slide");
  model.appendBodyToJoint(slide, pinocchio::Inertia::FromBox(2., 0.1, 0.1, 0.1));
  pinocchio::Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(1);
  BOOST_CHECK(!pinsettle::explainFreeFall(model, data, q, nullptr, nullptr, nullptr).empty());
  pinsettle::JointStops stops(model, false);
  stops.setLimit(slide, -0.5, 0.5);
  BOOST_CHECK(pinsettle::explainFreeFall(model, data, q, nullptr, nullptr, &stops).empty());
  // A horizontal slider feels no net force along its axis: no fall (it is neutral).
  pinocchio::Model flat;
  const pinocchio::JointIndex x =
    flat.addJoint(0, pinocchio::JointModelPX(), pinocchio::SE3::Identity(), "x");
  flat.appendBodyToJoint(x, pinocchio::Inertia::FromBox(2., 0.1, 0.1, 0.1));
  pinocchio::Data flat_data(flat);
  BOOST_CHECK(pinsettle::explainFreeFall(flat, flat_data, q, nullptr, nullptr, nullptr).empty());
}
