//
// Boost.Test cases of the pinsettle C++ core, built against the installed package.
//

#define BOOST_TEST_MODULE pinsettle_core
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <optional>
#include <string>
#include <vector>

// Counts heap allocations, to show that the step loop makes none. Eigen and Pinocchio allocate
// through malloc (Eigen's aligned_malloc), not operator new, so the C allocator itself is
// counted: malloc, calloc, realloc, the aligned variants and free are defined here. An
// executable's definitions take precedence over libc's for every shared library it loads too
// (libstdc++'s operator new calls this malloc), and they forward to glibc's own entry points
// (__libc_malloc, ...), which need no dlsym(RTLD_NEXT) bootstrap (dlsym itself allocates).
// Under AddressSanitizer the allocator is the sanitizer's: nothing is interposed, and the two
// tests that count are skipped (the sanitizer checks the memory instead).
#if defined(__SANITIZE_ADDRESS__)
  #define PINSETTLE_COUNT_MALLOC 0
#elif defined(__has_feature)
  #if __has_feature(address_sanitizer)
    #define PINSETTLE_COUNT_MALLOC 0
  #endif
#endif
#ifndef PINSETTLE_COUNT_MALLOC
  #define PINSETTLE_COUNT_MALLOC 1
#endif

static std::atomic<long> g_allocations{0};
static std::atomic<long> g_frees{0};

#if PINSETTLE_COUNT_MALLOC
extern "C"
{
  void * __libc_malloc(std::size_t size);
  void * __libc_calloc(std::size_t count, std::size_t size);
  void * __libc_realloc(void * p, std::size_t size);
  void * __libc_memalign(std::size_t alignment, std::size_t size);
  void __libc_free(void * p);

  void * malloc(std::size_t size) noexcept
  {
    ++g_allocations;
    return __libc_malloc(size);
  }
  void * calloc(std::size_t count, std::size_t size) noexcept
  {
    ++g_allocations;
    return __libc_calloc(count, size);
  }
  void * realloc(void * p, std::size_t size) noexcept
  {
    ++g_allocations;
    return __libc_realloc(p, size);
  }
  void * reallocarray(void * p, std::size_t count, std::size_t size) noexcept
  {
    if (size != 0 && count > static_cast<std::size_t>(-1) / size)
    {
      errno = ENOMEM;
      return nullptr;
    }
    return realloc(p, count * size);
  }
  void * memalign(std::size_t alignment, std::size_t size) noexcept
  {
    ++g_allocations;
    return __libc_memalign(alignment, size);
  }
  void * aligned_alloc(std::size_t alignment, std::size_t size) noexcept
  {
    return memalign(alignment, size);
  }
  int posix_memalign(void ** out, std::size_t alignment, std::size_t size) noexcept
  {
    if (alignment % sizeof(void *) != 0 || (alignment & (alignment - 1)) != 0)
      return EINVAL;
    void * p = memalign(alignment, size);
    if (p == nullptr)
      return ENOMEM;
    *out = p;
    return 0;
  }
  void free(void * p) noexcept
  {
    if (p != nullptr)
      ++g_frees;
    __libc_free(p);
  }
}
#endif // PINSETTLE_COUNT_MALLOC

namespace
{
  const std::string robots_dir = PINSETTLE_ROBOTS_DIR;

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

  // A planar chain of n links (hinges about y, 0.1 kg, 0.1 m each) hanging straight down at
  // q = 0, where every gravity torque is exactly zero.
  pinocchio::Model chain(int n)
  {
    pinocchio::Model model;
    pinocchio::JointIndex parent = 0;
    for (int k = 0; k < n; ++k)
    {
      const pinocchio::SE3 placement(
        Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., k == 0 ? 0. : -0.1));
      parent = model.addJoint(
        parent, pinocchio::JointModelRY(), placement, "joint" + std::to_string(k + 1));
      model.appendBodyToJoint(
        parent, pinocchio::Inertia(
                  0.1, Eigen::Vector3d(0., 0., -0.05), Eigen::Matrix3d::Identity() * 1e-4));
    }
    return model;
  }

  // A ball on a spherical joint: q is a quaternion, nq = 4 != nv = 3.
  pinocchio::Model sphericalPendulum()
  {
    pinocchio::Model model;
    const pinocchio::JointIndex j =
      model.addJoint(0, pinocchio::JointModelSpherical(), pinocchio::SE3::Identity(), "ball");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(2., Eigen::Vector3d(0., 0., -0.5), Eigen::Matrix3d::Identity() * 1e-2));
    return model;
  }

  std::vector<pinocchio::Model> robots()
  {
    std::vector<pinocchio::Model> models;
    models.push_back(
      pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf"));
    models.push_back(
      pinsettle::buildModelFromUrdf(robots_dir + "/panda_description/urdf/panda.urdf"));
    models.push_back(
      pinsettle::buildModelFromUrdf(robots_dir + "/solo_description/robots/solo12.urdf", true));
    models.push_back(sphericalPendulum());
    return models;
  }

  pinsettle::Settings tight()
  {
    pinsettle::Settings settings;
    settings.max_e = 1e-20;
    return settings;
  }
} // namespace

BOOST_AUTO_TEST_CASE(exact_energy_is_half_vT_M_v)
{
  std::srand(7);
  for (const pinocchio::Model & model : robots())
  {
    pinocchio::Data data(model), ref(model);
    const Eigen::VectorXd lower = Eigen::VectorXd::Constant(model.nq, -1.);
    const Eigen::VectorXd upper = Eigen::VectorXd::Constant(model.nq, 1.);
    for (int trial = 0; trial < 20; ++trial)
    {
      const Eigen::VectorXd q = pinocchio::randomConfiguration(model, lower, upper);
      const Eigen::VectorXd v = Eigen::VectorXd::Random(model.nv) * 3.;
      pinsettle::prebuilt::aba(model, data, q, v, Eigen::VectorXd::Zero(model.nv));
      const double ours = pinsettle::computeBodyKineticEnergy(model, data);
      const double theirs = pinocchio::computeKineticEnergy(model, ref, q, v);
      pinsettle::prebuilt::crba(model, ref, q);
      ref.M.triangularView<Eigen::StrictlyLower>() =
        ref.M.transpose().triangularView<Eigen::StrictlyLower>();
      const double quadratic = 0.5 * v.dot(ref.M * v);
      BOOST_CHECK_CLOSE(ours, theirs, 1e-10);
      BOOST_CHECK_CLOSE(ours, quadratic, 1e-10);
      // computeKineticEnergies (forward kinematics path) agrees with the ABA path.
      const std::pair<double, double> local = pinsettle::computeKineticEnergies(model, ref, q, v);
      BOOST_CHECK_CLOSE(local.first, ours, 1e-10);
      // The world convention's ABA (the solver's step) gives both measures alike: from data.ov,
      // data.oh and data.oinertias, not data.v.
      pinocchio::Data world(model);
      pinsettle::prebuilt::aba(
        model, world, q, v, Eigen::VectorXd::Zero(model.nv), pinocchio::Convention::WORLD);
      const pinocchio::Convention convention = pinocchio::Convention::WORLD;
      BOOST_CHECK_CLOSE(
        pinsettle::computeBodyKineticEnergy(model, world, convention), quadratic, 1e-10);
      BOOST_CHECK_CLOSE(
        pinsettle::computeSimplifiedKineticEnergy(model, world, convention), local.second, 1e-10);
    }
  }
}

BOOST_AUTO_TEST_CASE(simplified_energy_of_a_pendulum)
{
  // One body: |v_com|^2 + |w|^2 = (l w)^2 + w^2 for a bob at distance l.
  const pinocchio::Model model = pendulum(3., 0.7);
  pinocchio::Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, 0.4), v = Eigen::VectorXd::Constant(1, 2.);
  const std::pair<double, double> e = pinsettle::computeKineticEnergies(model, data, q, v);
  BOOST_CHECK_CLOSE(e.second, (0.7 * 2.) * (0.7 * 2.) + 4., 1e-12);
  BOOST_CHECK_CLOSE(e.first, 0.5 * (3. * 0.49 + 1e-3) * 4., 1e-12);
}

BOOST_AUTO_TEST_CASE(pendulum_settles_hanging_down)
{
  const pinocchio::Model model = pendulum();
  for (const pinsettle::EnergyMeasure measure :
       {pinsettle::EnergyMeasure::Exact, pinsettle::EnergyMeasure::Simplified})
  {
    for (const double kt : {0., 0.5, 0.9})
    {
      for (const bool backtrack : {false, true})
      {
        pinsettle::Settings settings = tight();
        settings.energy = measure;
        settings.kt = kt;
        settings.backtrack = backtrack;
        pinsettle::Solver solver(model);
        const pinsettle::Result result = solver.solve(Eigen::VectorXd::Constant(1, 1.), settings);
        BOOST_TEST_CONTEXT(
          "energy " << pinsettle::toString(measure) << " kt " << kt << " backtrack " << backtrack)
        {
          BOOST_CHECK(result.status == pinsettle::Status::Converged);
          BOOST_CHECK_LT(std::abs(result.q[0]), 1e-8); // analytic answer: 0
          BOOST_CHECK_LT(result.residual, 1e-8);
          pinocchio::Data data(model);
          BOOST_CHECK_LT(
            pinocchio::computeGeneralizedGravity(model, data, result.q).lpNorm<Eigen::Infinity>(),
            1e-8);
          BOOST_CHECK_GT(result.info.peaks, 0);
        }
      }
    }
  }
}

BOOST_AUTO_TEST_CASE(constant_torque_tilts_the_pendulum)
{
  // m g l sin(q*) = tau at the equilibrium; the residual includes the applied effort.
  const double m = 2., l = 0.5, g = 9.81, tau = 4.;
  const pinocchio::Model model = pendulum(m, l);
  const pinsettle::ConstantGeneralizedForce forces(Eigen::VectorXd::Constant(1, tau));
  pinsettle::Solver solver(model);
  const pinsettle::Result result = solver.solve(Eigen::VectorXd::Zero(1), tight(), &forces);
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  // With the bob on -z and a hinge about +y, gravity's generalized force is m g l sin(q).
  BOOST_CHECK_CLOSE(result.q[0], std::asin(tau / (m * g * l)), 1e-6);
  BOOST_CHECK_LT(result.residual, 1e-8);
}

BOOST_AUTO_TEST_CASE(spherical_joint_stays_on_its_manifold)
{
  const pinocchio::Model model = sphericalPendulum();
  Eigen::VectorXd q0(4);
  q0 << std::sin(0.5), 0.3, 0., std::cos(0.5); // (x, y, z, w), normalised below
  q0.normalize();
  pinsettle::Solver solver(model);
  const pinsettle::Result result = solver.solve(q0, tight());
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  BOOST_CHECK_SMALL(result.q.norm() - 1., 1e-12);
  BOOST_CHECK_LT(result.residual, 1e-8);
  // Hanging down: the body's z axis is vertical again.
  pinocchio::Data data(model);
  pinocchio::forwardKinematics(model, data, result.q);
  BOOST_CHECK_CLOSE(data.oMi[1].rotation()(2, 2), 1., 1e-12);
}

BOOST_AUTO_TEST_CASE(ur5_settles_to_a_stable_pose)
{
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  pinsettle::Settings settings;
  settings.max_e = 1e-16;
  pinsettle::Solver solver(model);
  const pinsettle::Result result = solver.solve(pinocchio::neutral(model), settings);
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  pinocchio::Data data(model);
  const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, result.q);
  BOOST_CHECK_LT(g.lpNorm<Eigen::Infinity>(), 1e-6);
  BOOST_CHECK_CLOSE(result.residual, g.lpNorm<Eigen::Infinity>(), 1e-6);
  // Stable: the finite-difference stiffness matrix dg/dq has no negative eigenvalue.
  Eigen::MatrixXd K(model.nv, model.nv);
  const double h = 1e-6;
  for (int k = 0; k < model.nv; ++k)
  {
    const Eigen::VectorXd dq = Eigen::VectorXd::Unit(model.nv, k) * h;
    const Eigen::VectorXd gp =
      pinocchio::computeGeneralizedGravity(model, data, pinocchio::integrate(model, result.q, dq));
    const Eigen::VectorXd gm =
      pinocchio::computeGeneralizedGravity(model, data, pinocchio::integrate(model, result.q, -dq));
    K.col(k) = (gp - gm) / (2. * h);
  }
  const Eigen::MatrixXd Ks = 0.5 * (K + K.transpose());
  const Eigen::VectorXd eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Ks).eigenvalues();
  BOOST_CHECK_GT(eig.minCoeff(), -1e-6);
}

BOOST_AUTO_TEST_CASE(allocation_counter_counts_what_eigen_and_new_allocate)
{
  if (!PINSETTLE_COUNT_MALLOC)
    return; // under AddressSanitizer
  // The guard below is only as good as its counter: Eigen's temporaries (aligned_malloc),
  // operator new and the C allocator must all show up.
  const Eigen::MatrixXd a = Eigen::MatrixXd::Random(20, 20);
  double sum = 0.;
  long before = g_allocations.load(), freed = g_frees.load();
  for (int k = 0; k < 2000; ++k)
  {
    const Eigen::MatrixXd b = a * a; // a heap temporary each time
    sum += b(k % 20, 0);
  }
  BOOST_CHECK(std::isfinite(sum));
  BOOST_CHECK_GE(g_allocations.load() - before, 2000);
  BOOST_CHECK_GE(g_frees.load() - freed, 2000);

  before = g_allocations.load();
  std::vector<double> * volatile v = new std::vector<double>(1000, 1.); // not elided
  BOOST_CHECK_GE(g_allocations.load() - before, 2);
  delete v;

  before = g_allocations.load();
  void * volatile p = std::malloc(64);
  void * volatile c = std::calloc(4, 16);
  void * volatile r = std::realloc(nullptr, 32);
  BOOST_CHECK_EQUAL(g_allocations.load() - before, 3);
  std::free(p);
  std::free(c);
  std::free(r);
}

BOOST_AUTO_TEST_CASE(step_loop_does_not_allocate)
{
  if (!PINSETTLE_COUNT_MALLOC)
    return; // under AddressSanitizer
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  pinsettle::Settings settings;
  settings.max_e = 0.; // never converges: runs exactly max_steps steps
  // No trace: its event list grows with the damping events (amortised, a few allocations).
  settings.dt = 1e-3; // the automatic step allocates when it re-estimates (a few times a run)
  settings.newton_takeover = false; // its tries at damping events allocate (and would end it)
  const Eigen::VectorXd q0 = pinocchio::neutral(model);
  long allocations[2], frees[2];
  const long steps[2] = {100, 20000};
  for (int k = 0; k < 2; ++k)
  {
    settings.max_steps = steps[k];
    pinsettle::Solver solver(model); // a fresh workspace each time, built before counting
    const long before = g_allocations.load(), freed = g_frees.load();
    const pinsettle::Result result = solver.solve(q0, settings);
    allocations[k] = g_allocations.load() - before;
    frees[k] = g_frees.load() - freed;
    BOOST_CHECK_EQUAL(result.info.steps, steps[k]);
  }
  BOOST_TEST_MESSAGE(
    "mallocs: " << allocations[0] << " for 100 steps, " << allocations[1] << " for 20000");
  // Allocations depend on the setup only (the result's vectors, the stiffness at the end), not
  // on the number of steps.
  BOOST_CHECK_GT(allocations[0], 0); // the result's q and v at least: the counter is live
  BOOST_CHECK_EQUAL(allocations[0], allocations[1]);
  BOOST_CHECK_EQUAL(frees[0], frees[1]);
}

BOOST_AUTO_TEST_CASE(default_settings_allocate_at_events_not_in_the_steps_between)
{
  // The default settings allocate where a run changes course (a step estimate, a Newton try
  // at a damping event, an assessment at a rest), not in the steps between. On the UR5 with
  // its stops, a joint spring and a point spring, released from its zero pose with kt = 0.9 (a
  // long run with many events), the allocations are counted step by step through the abort
  // callback (polled every step; it allocates nothing): the steps that allocate are at most
  // the events, and most steps allocate nothing.
  if (!PINSETTLE_COUNT_MALLOC)
    return; // under AddressSanitizer
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  const pinsettle::JointStops stops(model);
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(model.getJointId("elbow_joint"), 20., 0.5);
  springs.addPointSpring(
    0, Eigen::Vector3d(0.3, 0.3, 1.), model.getFrameId("tool0"), Eigen::Vector3d::Zero(), 50., 0.2);
  pinsettle::Settings settings; // automatic step, takeover and polish: the defaults
  settings.kt = 0.9;
  settings.check_every = 1;
  pinsettle::Solver solver(model, nullptr, &stops);
  long last = 0, allocating_steps = 0, polls = 0;
  const pinsettle::AbortCallback count = [&](const pinsettle::RunProgress &) {
    const long now = g_allocations.load();
    if (polls++ > 0 && now != last)
      ++allocating_steps;
    last = now;
    return false;
  };
  const pinsettle::Result result =
    solver.solve(pinocchio::neutral(model), settings, &springs, count);
  const long events = result.info.peaks + result.info.dt_estimates + result.info.pushes;
  BOOST_TEST_MESSAGE(
    "default settings: " << allocating_steps << " of " << polls << " steps allocate; "
                         << result.info.peaks << " damping events, " << result.info.dt_estimates
                         << " estimates, " << result.info.pushes << " pushes");
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  BOOST_CHECK_GT(polls, 100);
  BOOST_CHECK_LE(allocating_steps, events);
  BOOST_CHECK_LT(2 * allocating_steps, polls);
}

namespace
{
  // Returns NaN after a number of calls: the solver must stop and keep a finite state.
  struct PoisonAfter : pinsettle::ForceModel
  {
    mutable int calls = 0;
    int limit;
    explicit PoisonAfter(int n)
    : limit(n)
    {
    }
    void computeForces(
      const pinocchio::Model &,
      pinocchio::Data &,
      const Eigen::VectorXd &,
      const Eigen::VectorXd &,
      Eigen::VectorXd & tau,
      pinsettle::ForceVector &) const override
    {
      if (++calls > limit)
        tau.setConstant(std::nan(""));
    }
  };
} // namespace

BOOST_AUTO_TEST_CASE(non_finite_values_stop_with_diverged)
{
  const pinocchio::Model model = pendulum();
  const PoisonAfter poison(50);
  pinsettle::Solver solver(model);
  pinsettle::Settings settings = tight();
  settings.ds = 100;                // a run longer than the poison's 50 evaluations:
  settings.newton_takeover = false; // not ended by Newton at a damping event before them
  const pinsettle::Result result =
    solver.solve(Eigen::VectorXd::Constant(1, 1.), settings, &poison);
  // Every evaluation after the 50th is NaN: each roll-back to the start with half the step meets
  // it again, and after 30 halvings the run is declared diverged with the last good state.
  BOOST_CHECK(result.status == pinsettle::Status::Diverged);
  BOOST_CHECK_EQUAL(result.info.dt_reductions, 30);
  BOOST_CHECK(!result.reason.empty());
  BOOST_CHECK(result.q.allFinite());
  BOOST_CHECK(result.v.allFinite());
}

BOOST_AUTO_TEST_CASE(abort_callback_and_limits)
{
  const pinocchio::Model model = pendulum();
  pinsettle::Solver solver(model);
  pinsettle::Settings settings = tight();
  settings.check_every = 10;
  settings.dt = 1e-3; // 30 steps of 1 ms: still near the start
  std::vector<pinsettle::RunProgress> seen;
  std::vector<double> residuals;
  const pinsettle::Result aborted = solver.solve(
    Eigen::VectorXd::Constant(1, 1.), settings, nullptr, [&](const pinsettle::RunProgress & p) {
      seen.push_back(p);
      residuals.push_back(p.residual()); // computed now, at the state of this poll
      return seen.size() == 3;
    });
  BOOST_CHECK(aborted.status == pinsettle::Status::Aborted);
  BOOST_CHECK_EQUAL(aborted.info.steps, 30);
  BOOST_CHECK_GT(std::abs(aborted.q[0]), 0.5); // still swinging: the current state is kept

  // The callback saw the run where it stood: steps, time, the last step's energy and the
  // residual at the state it stopped in, recomputed here with Pinocchio.
  BOOST_REQUIRE_EQUAL(seen.size(), 3u);
  for (std::size_t k = 0; k < seen.size(); ++k)
  {
    BOOST_CHECK_EQUAL(seen[k].steps, 10 * std::int64_t(k + 1));
    BOOST_CHECK_CLOSE(seen[k].sim_time, 1e-3 * static_cast<double>(seen[k].steps), 1e-9);
    BOOST_CHECK_GT(seen[k].kinetic_energy, 0.);
    BOOST_CHECK_LE(seen[k].wall_time, aborted.info.wall_time);
  }
  BOOST_CHECK_LT(seen[0].kinetic_energy, seen[2].kinetic_energy); // falling from rest
  pinocchio::Data data(model);
  const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, aborted.q);
  BOOST_CHECK_CLOSE(residuals[2], g.lpNorm<Eigen::Infinity>(), 1e-9);
  BOOST_CHECK(std::isnan(pinsettle::RunProgress().residual())); // no solver behind it
  const double e_now = pinocchio::computeKineticEnergy(model, data, aborted.q, aborted.v);
  BOOST_CHECK_CLOSE(seen[2].kinetic_energy, e_now, 10.); // the step before the last one

  settings.max_steps = 5;
  BOOST_CHECK(
    solver.solve(Eigen::VectorXd::Constant(1, 1.), settings).status == pinsettle::Status::MaxSteps);
}

BOOST_AUTO_TEST_CASE(bad_input_is_rejected)
{
  const pinocchio::Model model = pendulum();
  pinsettle::Solver solver(model);
  const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(1);
  auto rejects = [&](pinsettle::Settings s) {
    BOOST_CHECK_THROW(solver.solve(q0, s), std::invalid_argument);
  };
  pinsettle::Settings s;
  s.dt = -1e-3;
  rejects(s);
  s = pinsettle::Settings();
  s.dt_safety = -0.1; // 0 is the measured default
  rejects(s);
  s = pinsettle::Settings();
  s.dt_safety = 1.5;
  rejects(s);
  s = pinsettle::Settings();
  s.dt = std::nan("");
  rejects(s);
  s = pinsettle::Settings();
  s.kt = 1.;
  rejects(s);
  s = pinsettle::Settings();
  s.kt = -0.1;
  rejects(s);
  s = pinsettle::Settings();
  s.ds = 0;
  rejects(s);
  s = pinsettle::Settings();
  s.max_e = -1.;
  rejects(s);
  BOOST_CHECK_THROW(solver.solve(Eigen::VectorXd::Zero(2)), std::invalid_argument);
  BOOST_CHECK_THROW(
    solver.solve(Eigen::VectorXd::Constant(1, std::nan(""))), std::invalid_argument);

  const pinocchio::Model ball = sphericalPendulum();
  pinsettle::Solver ball_solver(ball);
  try
  {
    ball_solver.solve(Eigen::Vector4d(0., 0., 0., 2.));
    BOOST_ERROR("a quaternion of norm 2 was accepted");
  }
  catch (const std::invalid_argument & e)
  {
    BOOST_CHECK_NE(std::string(e.what()).find("'ball'"), std::string::npos);
  }
  BOOST_CHECK_THROW(pinsettle::buildModelFromUrdf("/no/such/file.urdf"), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(time_scale_of_a_pendulum_is_its_natural_frequency)
{
  // Gravity torque m g l sin(q): K = m g l cos(q), M = m l^2 (+ the bob's 1e-3 inertia), and the
  // pull M^-1 m g l sin(q) per radian; omega^2 is the larger: (g / l) max(|cos q|, |sin q|).
  const double m = 2., l = 0.5, g = 9.81;
  const pinocchio::Model model = pendulum(m, l);
  pinocchio::Data data(model);
  for (const double q : {0., 0.4, 1.2, M_PI / 2., 2.5, M_PI})
  {
    const pinsettle::TimeScale scale =
      pinsettle::computeTimeScale(model, data, Eigen::VectorXd::Constant(1, q));
    const double inertia = m * l * l + 1e-3;
    const double omega2 =
      m * g * l / inertia * std::max(std::abs(std::cos(q)), std::abs(std::sin(q)));
    BOOST_CHECK_CLOSE(scale.omega_max, std::sqrt(omega2), 1e-6);
    BOOST_CHECK_EQUAL(scale.damping_rate, 0.);
    BOOST_CHECK_CLOSE(scale.critical_step, 2. / std::sqrt(omega2), 1e-6);
  }
}

BOOST_AUTO_TEST_CASE(time_scale_with_a_damper_is_the_semi_implicit_euler_limit)
{
  // Mass on a joint spring-damper, no gravity: x'' = -(k/m) x - (c/m) x'. Semi-implicit Euler
  // is stable for dt^2 k/m + 2 dt c/m < 4; check the limit and that the integrator really is
  // stable just below it and unstable just above.
  pinocchio::Model model = pendulum(3., 1.);
  model.gravity.setZero();
  const double inertia = 3. + 1e-3, k = 50., c = 4.;
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(1, k, 0., c);
  pinocchio::Data data(model);
  const pinsettle::TimeScale scale =
    pinsettle::computeTimeScale(model, data, Eigen::VectorXd::Zero(1), &springs);
  BOOST_CHECK_CLOSE(scale.omega_max, std::sqrt(k / inertia), 1e-6);
  BOOST_CHECK_CLOSE(scale.damping_rate, c / inertia, 1e-4);
  const double w2 = k / inertia, gamma = c / inertia, h = scale.critical_step;
  BOOST_CHECK_CLOSE(h * h * w2 + 2. * h * gamma, 4., 1e-4);
  const auto grows = [&](double dt) {
    double x = 1., v = 0.;
    for (int n = 0; n < 5000; ++n)
    {
      v += dt * (-w2 * x - gamma * v);
      x += dt * v;
    }
    return std::abs(x) > 1.;
  };
  BOOST_CHECK(!grows(0.99 * h));
  BOOST_CHECK(grows(1.01 * h));
}

namespace
{
  // A random symmetric positive definite matrix (dim n x n) with a spread of about 1e3.
  Eigen::MatrixXd randomMassMatrix(Eigen::Index n)
  {
    const Eigen::MatrixXd A = Eigen::MatrixXd::Random(n, n);
    return A * A.transpose() + 1e-3 * Eigen::MatrixXd::Identity(n, n);
  }
} // namespace

// Small mechanisms (up to 8 degrees of freedom) take a path in fixed-capacity storage: both
// paths must give the time scale's definition, checked here against Eigen's generalized solver.
BOOST_AUTO_TEST_CASE(time_scale_of_small_and_large_systems_is_its_definition)
{
  std::srand(7);
  for (const Eigen::Index n : {1, 3, 8, 9, 12})
  {
    const Eigen::MatrixXd M = randomMassMatrix(n);
    const Eigen::MatrixXd S = Eigen::MatrixXd::Random(n, n);
    const Eigen::MatrixXd K = S + S.transpose(); // indefinite: unstable modes count by |lambda|
    const Eigen::MatrixXd R = Eigen::MatrixXd::Random(n, n);
    const Eigen::MatrixXd D = 0.1 * R * R.transpose();
    const Eigen::VectorXd tau = Eigen::VectorXd::Random(n);

    const long before = g_allocations.load();
    const pinsettle::TimeScale scale = pinsettle::computeTimeScale(K, M, tau, &D, false);
    const long allocations = g_allocations.load() - before;

    const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> stiff(
      K, M, Eigen::EigenvaluesOnly);
    const double pull = M.llt().solve(tau).lpNorm<Eigen::Infinity>();
    const double omega2 = std::max(stiff.eigenvalues().cwiseAbs().maxCoeff(), pull);
    BOOST_CHECK_CLOSE(scale.omega_unscaled, std::sqrt(omega2), 1e-8);
    BOOST_CHECK_CLOSE(scale.omega_max, std::sqrt(omega2), 1e-8);
    const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> damped(
      D, M, Eigen::EigenvaluesOnly);
    const double gamma = damped.eigenvalues().maxCoeff();
    BOOST_CHECK_CLOSE(scale.damping_rate, gamma, 1e-8);
    BOOST_CHECK_CLOSE(
      scale.critical_step, 4. / (gamma + std::sqrt(gamma * gamma + 4. * omega2)), 1e-8);
    if (PINSETTLE_COUNT_MALLOC && n <= 8)
      BOOST_CHECK_EQUAL(allocations, 0); // nothing stiff to return: no heap at all
    else if (PINSETTLE_COUNT_MALLOC)
      BOOST_CHECK_GT(allocations, 0); // the counter is live
  }
}

// The polish's Newton step: the least-squares solution on K's range, nothing along its null
// space, from the small (fixed-capacity) and the large path alike. The neutral eigenvalue is
// zero, or small but above Eigen's own rank threshold (the noise of a differenced K): the cut
// must hold at the decomposition, not only at the solve (a cut set after it once made the solve
// read coefficients never computed).
BOOST_AUTO_TEST_CASE(rank_cut_solve_leaves_the_null_space_alone)
{
  std::srand(11);
  for (const double neutral : {0., 1e-12})
    for (const Eigen::Index n : {2, 3, 8, 9, 12})
    {
      BOOST_TEST_CONTEXT("n = " << n << ", neutral eigenvalue " << neutral)
      {
        const Eigen::HouseholderQR<Eigen::MatrixXd> qr(Eigen::MatrixXd::Random(n, n));
        const Eigen::MatrixXd Q = qr.householderQ();
        Eigen::VectorXd lambda = Eigen::VectorXd::LinSpaced(n, 1., 100.);
        lambda[n / 2] = neutral; // one neutral direction
        lambda[0] = -3.;         // and an unstable one, which Newton takes like any other
        const Eigen::MatrixXd K = Q * lambda.asDiagonal() * Q.transpose();
        const Eigen::VectorXd null = Q.col(n / 2);
        const Eigen::VectorXd y = Eigen::VectorXd::Random(n);
        const Eigen::VectorXd b = K * y + 0.5 * null; // a part off K's range

        const long before = g_allocations.load();
        const Eigen::VectorXd x = pinsettle::solveWithRankCut(K, b, 1e-10);
        const long allocations = g_allocations.load() - before;

        BOOST_CHECK_SMALL(null.dot(x), 1e-9);
        BOOST_CHECK_SMALL((K * x - K * y).lpNorm<Eigen::Infinity>(), 1e-8);
        // x itself and one workspace of Eigen's (a heap decomposition makes a dozen)
        if (PINSETTLE_COUNT_MALLOC && n <= 8)
          BOOST_CHECK_LE(allocations, 2);
        else if (PINSETTLE_COUNT_MALLOC)
          BOOST_CHECK_GT(allocations, 2);
      }
    }
}

BOOST_AUTO_TEST_CASE(automatic_step_settles_a_stiff_spring_next_to_a_heavy_body)
{
  // A 10 g slider on a 1e8 N/m spring, carried by a 10 kg pendulum: omega ~ 1e5 rad/s next to
  // ~3 rad/s. Without stiff-mode scaling the automatic step resolves the stiff mode; with it
  // (the default) the stiff mode is slowed to the pendulum's pace. Both settle to the same,
  // right answer; scaling takes far fewer steps.
  pinocchio::Model model = pendulum(10., 1.);
  const pinocchio::JointIndex slider = model.addJoint(
    1, pinocchio::JointModelPZ(),
    pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., -1.)), "slider");
  model.appendBodyToJoint(
    slider, pinocchio::Inertia(0.01, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * 1e-6));
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(slider, 1e8, 0.);
  pinsettle::Solver solver(model);
  std::int64_t steps[2] = {0, 0};
  for (const bool scale : {false, true})
  {
    BOOST_TEST_CONTEXT("scale_stiff_modes " << scale)
    {
      pinsettle::Settings settings;
      settings.max_e = 1e-18;
      settings.scale_stiff_modes = scale;
      const pinsettle::Result result = solver.solve(Eigen::Vector2d(0.8, 0.), settings, &springs);
      BOOST_CHECK(result.status == pinsettle::Status::Converged);
      BOOST_CHECK(result.stability == pinsettle::Stability::Stable);
      BOOST_CHECK_EQUAL(result.info.dt_reductions, 0);
      // Hanging down, the slider sags by m g / k along the pendulum.
      BOOST_CHECK_SMALL(result.q[0], 1e-8);
      BOOST_CHECK_CLOSE(result.q[1], -0.01 * 9.81 / 1e8, 1e-3);
      if (scale)
      {
        BOOST_CHECK_EQUAL(result.info.scaled_modes, 1);
        BOOST_CHECK_GT(result.info.dt, 1e-2); // the pendulum's pace: 0.2 * 2 / sqrt(g / l) ~ 0.13 s
      }
      else
      {
        BOOST_CHECK_EQUAL(result.info.scaled_modes, 0);
        BOOST_CHECK_LT(result.info.dt, 2e-5); // below 2 / omega_max of the stiff mode
      }
      steps[scale ? 1 : 0] = result.info.steps;
    }
  }
  BOOST_CHECK_LT(10 * steps[1], steps[0]);
}

BOOST_AUTO_TEST_CASE(stiff_mode_scaling_slows_the_stiff_mode_and_keeps_the_soft_one)
{
  // A stiff joint spring on a light link at the end of a heavy pendulum, at its equilibrium
  // (no pull). Modes of K phi = lambda M phi: a soft pendulum mode and a stiff spring mode.
  // With the added inertia W^T diag(d) W the stiff mode's eigenvalue drops to the soft one's,
  // and the soft mode stays where it was.
  pinocchio::Model model = pendulum(10., 1.);
  const pinocchio::JointIndex j2 = model.addJoint(
    1, pinocchio::JointModelRY(),
    pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., -1.)), "light");
  model.appendBodyToJoint(
    j2,
    pinocchio::Inertia(0.01, Eigen::Vector3d(0., 0., -0.1), Eigen::Matrix3d::Identity() * 1e-6));
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(j2, 1e6, 0.);
  pinocchio::Data data(model);
  const Eigen::Vector2d q = Eigen::Vector2d::Zero();
  const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, data, q, &springs);
  pinsettle::prebuilt::crba(model, data, q);
  Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
  const Eigen::VectorXd before =
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd>(K, M, Eigen::EigenvaluesOnly)
      .eigenvalues();
  BOOST_REQUIRE_GT(before[1], pinsettle::kStiffGap * before[0]);

  const pinsettle::TimeScale plain = pinsettle::computeTimeScale(model, data, q, &springs, false);
  BOOST_CHECK_EQUAL(plain.stiff_masses.size(), 0);
  BOOST_CHECK_CLOSE(plain.omega_max, std::sqrt(before[1]), 1e-6);

  const pinsettle::TimeScale scaled = pinsettle::computeTimeScale(model, data, q, &springs, true);
  BOOST_REQUIRE_EQUAL(scaled.stiff_masses.size(), 1);
  BOOST_CHECK_CLOSE(scaled.omega_unscaled, plain.omega_max, 1e-9);
  BOOST_CHECK_CLOSE(scaled.omega_max, std::sqrt(before[0]), 1e-6);
  M += scaled.stiff_momenta.transpose() * scaled.stiff_masses.asDiagonal() * scaled.stiff_momenta;
  const Eigen::VectorXd after =
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd>(K, M, Eigen::EigenvaluesOnly)
      .eigenvalues();
  BOOST_CHECK_CLOSE(after[0], before[0], 1e-6);
  BOOST_CHECK_CLOSE(after[1], before[0], 1e-6);
}

BOOST_AUTO_TEST_CASE(constant_torque_on_a_free_wheel_has_no_equilibrium)
{
  pinocchio::Model model;
  const pinocchio::JointIndex j =
    model.addJoint(0, pinocchio::JointModelRUBY(), pinocchio::SE3::Identity(), "wheel");
  model.appendBodyToJoint(
    j, pinocchio::Inertia(1., Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * 0.02));
  const pinsettle::ConstantGeneralizedForce torque(Eigen::VectorXd::Constant(1, 1.));
  pinsettle::Solver solver(model);
  const pinsettle::Result result =
    solver.solve(pinocchio::neutral(model), pinsettle::Settings(), &torque);
  BOOST_CHECK(result.status == pinsettle::Status::NoEquilibrium);
  BOOST_CHECK(result.reason.find("falls without bound") != std::string::npos);
  BOOST_CHECK_LE(result.info.steps, 2 * 100 * 1024 + 1);
}

BOOST_AUTO_TEST_CASE(newton_polish_stops_once_a_step_moves_q_by_its_round_off_only)
{
  // Hanging straight down, a chain's gravity torques are about its angles themselves, with no
  // round-off floor: a polish that iterates while the residual falls chases it into denormals
  // (10 iterations on 20 links). Once the next step would be below q's round-off it must stop.
  const pinocchio::Model model = chain(8);
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(model.nq);
  q0[0] = 0.5 * M_PI; // horizontal
  pinsettle::Solver solver(model);
  const pinsettle::Result result = solver.solve(q0, pinsettle::Settings());
  BOOST_REQUIRE(result.status == pinsettle::Status::Converged);
  BOOST_CHECK(result.info.polished);
  BOOST_CHECK_GE(result.info.polish_iterations, 1);
  BOOST_CHECK_LE(result.info.polish_iterations, 4);
  // The answer is at round-off: recomputed outside the solver, the residual is a tiny share of
  // the start's force, and a further Newton step would not move q by more than its round-off.
  pinocchio::Data data(model);
  const double start_force =
    pinocchio::computeGeneralizedGravity(model, data, q0).lpNorm<Eigen::Infinity>();
  const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, result.q);
  BOOST_CHECK_LT(g.lpNorm<Eigen::Infinity>(), 1e-13 * start_force);
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(model.nv, model.nv);
  pinocchio::computeGeneralizedGravityDerivatives(model, data, result.q, K);
  const Eigen::VectorXd next = K.fullPivLu().solve(-g);
  BOOST_CHECK_LT(next.lpNorm<Eigen::Infinity>(), 1e-14);
  BOOST_CHECK(result.stability == pinsettle::Stability::Stable);
  for (Eigen::Index k = 0; k < model.nq; ++k) // straight down (up to whole turns)
    BOOST_CHECK_LT(std::abs(std::remainder(result.q[k], 2. * M_PI)), 1e-9);
}

BOOST_AUTO_TEST_CASE(newton_polish_brings_the_residual_to_round_off_and_keeps_the_rest)
{
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  pinsettle::Solver solver(model);
  pinsettle::Settings settings;
  settings.polish = true;
  settings.newton_takeover = false; // the polish after the run, from where the run stops
  settings.max_e = 1e-3;            // a loose stopping bound: the run leaves the polish work to do
  settings.ds = 100; // near the rest: with the default window of 10 the run stops 0.04 rad off
  const pinsettle::Result result = solver.solve(pinocchio::neutral(model), settings);
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  BOOST_CHECK(result.info.polished);
  BOOST_CHECK_GE(result.info.polish_iterations, 1);
  BOOST_CHECK_GT(result.info.residual_before_polish, 1e-9);
  BOOST_CHECK_LT(result.residual, 1e-12);
  BOOST_CHECK(result.stability != pinsettle::Stability::Unstable);
  // Recomputed outside the solver.
  pinocchio::Data data(model);
  BOOST_CHECK_LT(
    pinocchio::computeGeneralizedGravity(model, data, result.q).lpNorm<Eigen::Infinity>(), 1e-12);
  // The same rest as without the polish, closer to exact.
  settings.polish = false;
  const pinsettle::Result plain = solver.solve(pinocchio::neutral(model), settings);
  BOOST_CHECK_EQUAL(plain.residual, result.info.residual_before_polish);
  BOOST_CHECK_LT(pinocchio::difference(model, plain.q, result.q).lpNorm<Eigen::Infinity>(), 1e-5);
}

BOOST_AUTO_TEST_CASE(newton_takes_over_at_a_damping_event_at_the_same_strict_minimum)
{
  // The pendulum released at 1 rad: with the takeover Newton ends the run at an early damping
  // event; without it (the default) the damping goes on until the energy stays below max_e.
  // Both rest hanging straight down (g(q) = 0 recomputed with Pinocchio), the takeover's at
  // round-off, in fewer steps.
  const pinocchio::Model model = pendulum();
  pinsettle::Solver solver(model);
  pinsettle::Settings settings;
  settings.newton_takeover = true;
  const Eigen::VectorXd q0 = Eigen::VectorXd::Constant(1, 1.);
  const pinsettle::Result taken = solver.solve(q0, settings);
  settings.newton_takeover = false;
  const pinsettle::Result damped = solver.solve(q0, settings);
  BOOST_REQUIRE(taken.status == pinsettle::Status::Converged);
  BOOST_REQUIRE(damped.status == pinsettle::Status::Converged);
  BOOST_CHECK_LT(taken.info.steps, damped.info.steps);
  BOOST_CHECK(taken.info.polished);
  BOOST_CHECK_GT(taken.info.residual_before_polish, taken.residual);
  BOOST_CHECK(taken.stability == pinsettle::Stability::Stable);
  pinocchio::Data data(model);
  const double weight = model.inertias[1].mass() * 9.81 * model.inertias[1].lever().norm();
  BOOST_CHECK_LE(
    pinocchio::computeGeneralizedGravity(model, data, taken.q).lpNorm<Eigen::Infinity>(),
    1e-14 * weight);
  BOOST_CHECK_LT(pinocchio::difference(model, damped.q, taken.q).lpNorm<Eigen::Infinity>(), 1e-12);
}

BOOST_AUTO_TEST_CASE(newton_from_another_methods_state_takes_over_near_a_rest_only)
{
  // settleByNewton is the takeover a run tries at a damping event, offered to other methods:
  // from 0.05 rad off the UR5's rest it ends at that rest to round-off (g(q) recomputed with
  // Pinocchio); from the start, 1.3 rad and more away, it refuses and leaves q to the method.
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  pinsettle::Solver solver(model);
  const pinsettle::Settings settings;
  const Eigen::VectorXd q0 = pinocchio::neutral(model);
  const pinsettle::Result rest = solver.solve(q0, settings);
  BOOST_REQUIRE(rest.status == pinsettle::Status::Converged);
  BOOST_CHECK(!solver.settleByNewton(q0, settings));

  // Off along the joints that carry the arm's weight (shoulder lift, elbow, wrist 1): the base
  // and last joints turn freely (neutral directions), and Newton leaves those alone.
  Eigen::VectorXd off = Eigen::VectorXd::Zero(model.nv);
  off.segment(1, 3).setConstant(0.05);
  const Eigen::VectorXd near = pinocchio::integrate(model, rest.q, off);
  const std::optional<pinsettle::Solver::NewtonRest> took = solver.settleByNewton(near, settings);
  BOOST_REQUIRE(took);
  BOOST_CHECK_GE(took->iterations, 1);
  BOOST_CHECK_GT(took->residual_from, 1.);
  pinocchio::Data data(model);
  const double g_near =
    pinocchio::computeGeneralizedGravity(model, data, near).lpNorm<Eigen::Infinity>();
  const double g_took =
    pinocchio::computeGeneralizedGravity(model, data, took->q).lpNorm<Eigen::Infinity>();
  BOOST_CHECK_CLOSE(took->residual_from, g_near, 1e-9);
  BOOST_CHECK_EQUAL(took->residual, g_took);
  BOOST_CHECK_LT(g_took, 1e-12);
  BOOST_CHECK(took->stability == rest.stability);
  BOOST_CHECK_LT(pinocchio::difference(model, rest.q, took->q).lpNorm<Eigen::Infinity>(), 1e-9);

  // So close that Newton's first stride lands at round-off, and the next step, already at the
  // round-off of q, no longer lowers the residual: converged, taken (it was once counted a
  // stall, and the run damped on for twice the steps).
  for (const double c : {0.005, 0.02})
  {
    const Eigen::VectorXd closer = pinocchio::integrate(model, rest.q, c / 0.05 * off);
    const std::optional<pinsettle::Solver::NewtonRest> at = solver.settleByNewton(closer, settings);
    BOOST_REQUIRE_MESSAGE(at, "not taken " << c << " rad off");
    BOOST_CHECK_GE(at->iterations, 1);
    BOOST_CHECK_LT(
      pinocchio::computeGeneralizedGravity(model, data, at->q).lpNorm<Eigen::Infinity>(), 1e-12);
    BOOST_CHECK_LT(pinocchio::difference(model, rest.q, at->q).lpNorm<Eigen::Infinity>(), 1e-9);
  }

  // The polish of a rest to 1e-4 rad: closer to exact, the same rest.
  const Eigen::VectorXd rough = pinocchio::integrate(model, rest.q, 2e-3 * off);
  const pinsettle::Solver::NewtonRest polished = solver.polishRest(rough);
  BOOST_CHECK_GE(polished.iterations, 1);
  BOOST_CHECK_LT(polished.residual, 1e-12);
  BOOST_CHECK_LT(
    pinocchio::computeGeneralizedGravity(model, data, polished.q).lpNorm<Eigen::Infinity>(), 1e-12);
  BOOST_CHECK_LT(pinocchio::difference(model, rest.q, polished.q).lpNorm<Eigen::Infinity>(), 1e-9);

  // A bad q is named; a solver with constraints refuses (their state belongs to a run).
  BOOST_CHECK_THROW(
    solver.settleByNewton(Eigen::VectorXd::Zero(2), settings), std::invalid_argument);
  pinsettle::JointStops stops(model);
  pinsettle::Solver stopped(model, nullptr, &stops);
  BOOST_CHECK_THROW(stopped.polishRest(rest.q), std::logic_error);
}

BOOST_AUTO_TEST_CASE(joint_inertia_brings_each_joint_down_to_the_slowest_and_not_below_the_modes)
{
  // Hanging straight down (no pull), a chain's joints swing at rates sqrt(K_ii / M_ii) from
  // the bottom link's (fast) to the top one's (slow): every joint given an inertia ends at the
  // slowest rate, which is not below the slowest mode (Rayleigh), and none is slowed past it.
  const pinocchio::Model model = chain(8);
  pinocchio::Data data(model);
  const Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(model.nv, model.nv);
  pinocchio::computeGeneralizedGravityDerivatives(model, data, q, K);
  pinsettle::prebuilt::crba(model, data, q);
  const Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
  const Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
  const Eigen::VectorXd added = pinsettle::computeJointInertia(K, M.diagonal(), tau);
  BOOST_REQUIRE_EQUAL(added.size(), model.nv);
  double slowest = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < model.nv; ++i)
    slowest = std::min(slowest, K(i, i) / M(i, i));
  const double lambda_min =
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd>(K, M, Eigen::EigenvaluesOnly)
      .eigenvalues()
      .minCoeff();
  BOOST_CHECK_GT(lambda_min, 0.);
  BOOST_CHECK_GE(slowest, lambda_min * (1. - 1e-12));
  int given = 0;
  for (Eigen::Index i = 0; i < model.nv; ++i)
  {
    BOOST_CHECK_GE(added[i], 0.);
    BOOST_CHECK_CLOSE(K(i, i) / (M(i, i) + added[i]), slowest, 1e-9); // percent
    given += added[i] > 0. ? 1 : 0;
  }
  BOOST_CHECK_GE(given, model.nv - 1); // all but the slowest joint
  // With the new masses the spread of the modes is far smaller than without.
  Eigen::MatrixXd scaled = M;
  scaled.diagonal() += added;
  const auto spread = [&](const Eigen::MatrixXd & mass) {
    const Eigen::VectorXd l =
      Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd>(K, mass, Eigen::EigenvaluesOnly)
        .eigenvalues();
    return l.maxCoeff() / l.minCoeff();
  };
  BOOST_CHECK_LT(spread(scaled), 0.1 * spread(M));

  // Nothing holds or pulls: no rate to match, no inertia.
  BOOST_CHECK_EQUAL(
    pinsettle::computeJointInertia(
      Eigen::MatrixXd::Zero(3, 3), Eigen::VectorXd::Ones(3), Eigen::VectorXd::Zero(3))
      .cwiseAbs()
      .maxCoeff(),
    0.);
  // A joint with a rate far below the others' slows them kJointInertiaSpread-fold at most.
  const Eigen::MatrixXd soft = Eigen::Vector3d(1., 1e-8, 1.).asDiagonal();
  const Eigen::VectorXd capped =
    pinsettle::computeJointInertia(soft, Eigen::VectorXd::Ones(3), Eigen::VectorXd::Zero(3));
  BOOST_CHECK_CLOSE(1. / (1. + capped[0]), 1. / pinsettle::kJointInertiaSpread, 1e-9);
  BOOST_CHECK_EQUAL(capped[1], 0.);
}

BOOST_AUTO_TEST_CASE(an_estimate_takes_no_energy_where_it_adds_inertia_and_counts_what_it_takes)
{
  // Estimates along a moving chain, each re-choosing the joints' added inertia: the energy
  // after (the bodies' plus the added inertia's, at the new velocity) is the energy before less
  // what the estimate reports taken, which is nothing where inertia was added (the velocity is
  // scaled to keep the energy) and the removed inertia's share where some was taken away. The
  // runaway monitor sums what is taken as energy removed from the run.
  const pinocchio::Model model = chain(5);
  pinsettle::Settings settings;
  settings.scale_joint_inertia = pinsettle::Toggle::On;
  pinsettle::StepController control(model, nullptr);
  control.start(settings, nullptr);
  pinocchio::Data data(model), scratch(model);
  const auto energy = [&](const Eigen::VectorXd & q, const Eigen::VectorXd & v) {
    pinsettle::prebuilt::crba(model, scratch, q);
    const Eigen::MatrixXd M = scratch.M.selfadjointView<Eigen::Upper>();
    return 0.5 * v.dot(M * v) + control.addedEnergy(v);
  };
  Eigen::VectorXd v = Eigen::VectorXd::LinSpaced(model.nv, 0.3, -0.2);
  int added = 0, taken = 0;
  for (int k = 0; k < 8; ++k)
  {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(model.nq);
    q[0] = 0.25 * M_PI * k; // round the circle: pulled, hanging, upright
    q[2] = 0.3 * std::sin(k);
    const Eigen::VectorXd v_before = v;
    const double before = energy(q, v);
    const double loss = control.estimate(data, q, v, 100 * k);
    const double after = energy(q, v);
    BOOST_TEST_CONTEXT("estimate " << k)
    {
      BOOST_CHECK_GE(loss, 0.);
      BOOST_CHECK_SMALL(after - (before - loss), 1e-12 * before);
      if (loss == 0. && v != v_before)
        ++added; // scaled down to keep the energy
      if (loss > 0.)
      {
        BOOST_CHECK(v == v_before); // the velocity kept, the removed inertia's share gone
        ++taken;
      }
    }
  }
  BOOST_CHECK_GT(control.scaledJoints(), 0);
  BOOST_CHECK_GT(added, 0);
  BOOST_CHECK_GT(taken, 0);
}

BOOST_AUTO_TEST_CASE(joint_inertia_by_default_from_twenty_degrees_of_freedom_without_contacts)
{
  // The rule of Toggle::Auto (the default), and On and Off forcing it either way.
  pinsettle::Settings settings;
  BOOST_CHECK(settings.scale_joint_inertia == pinsettle::Toggle::Auto);
  BOOST_CHECK(
    !pinsettle::effectiveJointInertia(settings, pinsettle::kJointInertiaMinDofs - 1, false));
  BOOST_CHECK(pinsettle::effectiveJointInertia(settings, pinsettle::kJointInertiaMinDofs, false));
  BOOST_CHECK(!pinsettle::effectiveJointInertia(settings, 100, true)); // ground contacts
  settings.scale_joint_inertia = pinsettle::Toggle::On;
  BOOST_CHECK(pinsettle::effectiveJointInertia(settings, 2, true));
  settings.scale_joint_inertia = pinsettle::Toggle::Off;
  BOOST_CHECK(!pinsettle::effectiveJointInertia(settings, 100, false));

  // And the solver applies it: a chain of 20 links released horizontal gets it by default, one
  // of 19 does not, both resting straight down (Pinocchio's gravity vanishes there).
  for (const int links : {19, 20})
  {
    const pinocchio::Model model = chain(links);
    Eigen::VectorXd q0 = Eigen::VectorXd::Zero(model.nq);
    q0[0] = 0.5 * M_PI;
    pinsettle::Solver solver(model);
    const pinsettle::Result r = solver.solve(q0, pinsettle::Settings());
    BOOST_REQUIRE(r.status == pinsettle::Status::Converged);
    BOOST_CHECK_EQUAL(r.info.scaled_joints > 0, links >= pinsettle::kJointInertiaMinDofs);
    pinocchio::Data data(model);
    const double start_force =
      pinocchio::computeGeneralizedGravity(model, data, q0).lpNorm<Eigen::Infinity>();
    const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, r.q);
    BOOST_CHECK_LT(g.lpNorm<Eigen::Infinity>(), 1e-12 * start_force);
  }
}

BOOST_AUTO_TEST_CASE(joint_inertia_settles_a_chain_at_the_same_rest_in_fewer_steps)
{
  // Released horizontal, the chain's run is set by its fast bottom links; with their inertia
  // raised it comes to the same rest (straight down, checked with Pinocchio) in fewer steps.
  const pinocchio::Model model = chain(12);
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(model.nq);
  q0[0] = 0.5 * M_PI;
  pinsettle::Settings plain, scaled;
  scaled.scale_joint_inertia = pinsettle::Toggle::On;
  const Eigen::VectorXd armature = model.armature;
  pinsettle::Solver solver(model);
  const pinsettle::Result a = solver.solve(q0, plain);
  const pinsettle::Result b = solver.solve(q0, scaled);
  BOOST_REQUIRE(a.status == pinsettle::Status::Converged);
  BOOST_REQUIRE(b.status == pinsettle::Status::Converged);
  BOOST_CHECK_EQUAL(a.info.scaled_joints, 0);
  BOOST_CHECK_GE(b.info.scaled_joints, model.nv / 2);
  BOOST_CHECK(model.armature == armature); // the user's model is left as it was
  pinocchio::Data data(model);
  const double start_force =
    pinocchio::computeGeneralizedGravity(model, data, q0).lpNorm<Eigen::Infinity>();
  const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, b.q);
  BOOST_CHECK_LT(g.lpNorm<Eigen::Infinity>(), 1e-12 * start_force);
  BOOST_CHECK(b.stability == pinsettle::Stability::Stable);
  for (Eigen::Index k = 0; k < model.nq; ++k)
    BOOST_CHECK_LT(std::abs(std::remainder(b.q[k], 2. * M_PI)), 1e-9);
  BOOST_TEST_MESSAGE(
    "steps: " << a.info.steps << " plain, " << b.info.steps << " with joint inertia");
  BOOST_CHECK_LT(2 * b.info.steps, a.info.steps);
  // The run's end energies are the bodies' (the fictitious inertia is not reported).
  BOOST_CHECK_LE(b.info.kinetic_energy, 10. * scaled.max_e);

  // The same solver after the model changed (gravity tilted): the run of a fresh solver (the
  // added inertia rides on a copy of the model made each run). Without the polish, which would
  // mend a run on the old model's dynamics.
  pinsettle::Settings unpolished = scaled;
  unpolished.polish = false;
  pinocchio::Model tilted = model;
  pinsettle::Solver reused(tilted);
  BOOST_REQUIRE(reused.solve(q0, unpolished).status == pinsettle::Status::Converged);
  tilted.gravity.linear(Eigen::Vector3d(3., 0., -9.81));
  const pinsettle::Result again = reused.solve(q0, unpolished);
  const pinsettle::Result fresh = pinsettle::Solver(tilted).solve(q0, unpolished);
  BOOST_REQUIRE(again.status == pinsettle::Status::Converged);
  BOOST_CHECK_EQUAL(again.info.steps, fresh.info.steps);
  BOOST_CHECK_LT((again.q - fresh.q).lpNorm<Eigen::Infinity>(), 1e-12);
  BOOST_CHECK_LT(
    pinocchio::computeGeneralizedGravity(tilted, data, again.q).lpNorm<Eigen::Infinity>(),
    1e-4 * start_force);
  BOOST_CHECK_GT(again.q.cwiseAbs().maxCoeff(), 0.1); // not straight down any more

  // Not with the simplified energy (it would not see the added inertia), nor a fixed step.
  scaled.energy = pinsettle::EnergyMeasure::Simplified;
  BOOST_CHECK_EQUAL(solver.solve(q0, scaled).info.scaled_joints, 0);
  scaled.energy = pinsettle::EnergyMeasure::Exact;
  scaled.dt = 1e-3;
  scaled.max_steps = 50;
  BOOST_CHECK_EQUAL(solver.solve(q0, scaled).info.scaled_joints, 0);
}
