//
// Boost.Test cases of joint stops: where they come from, the impact, the held dynamics, and
// rests against stops checked by their conditions (recomputed with Pinocchio, not the solver).
//

#define BOOST_TEST_MODULE pinsettle_stops
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace
{
  const std::string robots_dir = PINSETTLE_ROBOTS_DIR;
  constexpr double kInf = std::numeric_limits<double>::infinity();

  // A chain of n links of mass m and length l hanging from hinges about y (down at q = 0).
  pinocchio::Model chain(int n, double m = 1., double l = 0.5)
  {
    pinocchio::Model model;
    pinocchio::JointIndex parent = 0;
    for (int k = 0; k < n; ++k)
    {
      const pinocchio::SE3 placement(
        Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., k == 0 ? 0. : -l));
      parent =
        model.addJoint(parent, pinocchio::JointModelRY(), placement, "j" + std::to_string(k + 1));
      model.addJointFrame(parent);
      model.appendBodyToJoint(
        parent, pinocchio::Inertia(
                  m, Eigen::Vector3d(0., 0., -0.5 * l), Eigen::Matrix3d::Identity() * 1e-2));
    }
    return model;
  }

  // The conditions of a rest against stops, from Pinocchio's gravity alone: inside the
  // ranges, zero force off the stops, force into the stop at each stop. Returns the worst
  // violation.
  double restViolation(
    const pinocchio::Model & model, const pinsettle::JointStops & stops, const Eigen::VectorXd & q)
  {
    pinocchio::Data data(model);
    const Eigen::VectorXd tau = pinocchio::computeGeneralizedGravity(model, data, q);
    Eigen::VectorXd violation = tau.cwiseAbs();
    for (const pinsettle::JointStops::Stop & s : stops.stops())
    {
      const double x = q[s.iq];
      if (x < s.lower || x > s.upper)
        return kInf;
      if (x == s.lower)
        violation[s.iv] = std::max(0., -tau[s.iv]);
      else if (x == s.upper)
        violation[s.iv] = std::max(0., tau[s.iv]);
    }
    return violation.maxCoeff();
  }
} // namespace

BOOST_AUTO_TEST_CASE(stops_come_from_the_model_limits)
{
  pinocchio::Model model = chain(4);
  // j1 limited, j2 equal limits (the URDF default), j3 unbounded (a model built in code),
  // j4 one-sided.
  model.lowerPositionLimit << -0.5, 0., -std::numeric_limits<double>::max(), -kInf;
  model.upperPositionLimit << 1., 0., std::numeric_limits<double>::max(), 0.2;
  const pinsettle::JointStops stops(model);
  BOOST_REQUIRE_EQUAL(stops.stops().size(), 2u);
  BOOST_CHECK_EQUAL(stops.stops()[0].joint, 1u);
  BOOST_CHECK_EQUAL(stops.stops()[0].lower, -0.5);
  BOOST_CHECK_EQUAL(stops.stops()[1].joint, 4u);
  BOOST_CHECK(std::isinf(stops.stops()[1].lower));
  BOOST_REQUIRE_EQUAL(stops.equalLimitJoints().size(), 1u);
  BOOST_CHECK_EQUAL(stops.equalLimitJoints()[0], 2u);
  BOOST_CHECK(pinsettle::JointStops(model, false).empty());
}

BOOST_AUTO_TEST_CASE(limits_of_joints_of_several_entries_are_listed_unless_placeholders)
{
  // Pinocchio's placeholders (+-max; +-1.01, as its parsers fill a quaternion, a continuous
  // joint's cos and sin, and the MJCF parser a free joint's translation) are no limit; any
  // other bound on such a joint is a limit no stop applies.
  pinocchio::Model model;
  const pinocchio::SE3 at = pinocchio::SE3::Identity();
  const pinocchio::Inertia body = pinocchio::Inertia::FromSphere(1., 0.1);
  const std::vector<pinocchio::JointIndex> joints = {
    model.addJoint(0, pinocchio::JointModelFreeFlyer(), at, "free"),
    model.addJoint(0, pinocchio::JointModelPlanar(), at, "planar"),
    model.addJoint(0, pinocchio::JointModelSpherical(), at, "ball"),
    model.addJoint(0, pinocchio::JointModelRUBY(), at, "wheel"),
    model.addJoint(0, pinocchio::JointModelRY(), at, "hinge")};
  for (const pinocchio::JointIndex j : joints)
    model.appendBodyToJoint(j, body);
  const auto entries = [&](pinocchio::JointIndex j) {
    return std::make_pair(model.idx_qs[j], model.nqs[j]);
  };
  model.lowerPositionLimit.setConstant(-std::numeric_limits<double>::max());
  model.upperPositionLimit.setConstant(std::numeric_limits<double>::max());
  for (const pinocchio::JointIndex j : {joints[0], joints[2], joints[3]})
  {
    model.lowerPositionLimit.segment(entries(j).first, entries(j).second).setConstant(-1.01);
    model.upperPositionLimit.segment(entries(j).first, entries(j).second).setConstant(1.01);
  }
  // A unit-norm entry bounded by 1 or more never reaches its bound: no limit either.
  model.upperPositionLimit[entries(joints[1]).first + 2] = 1.;
  BOOST_CHECK(pinsettle::JointStops(model).unappliedLimitJoints().empty());
  BOOST_CHECK(pinsettle::JointStops(model).stops().empty());

  // Limits of their own: a planar joint's x, a ball's quaternion entry below 1, a free joint's
  // height.
  model.lowerPositionLimit[entries(joints[1]).first] = -0.5;
  model.upperPositionLimit[entries(joints[2]).first] = 0.3;
  model.lowerPositionLimit[entries(joints[0]).first + 2] = 0.;
  const pinsettle::JointStops stops(model);
  const std::vector<pinocchio::JointIndex> expected = {joints[0], joints[1], joints[2]};
  BOOST_CHECK(stops.unappliedLimitJoints() == expected);
  // A translation bound above 1 is a limit: the unit-norm entries' threshold is not applied to
  // it (x below 2 alone).
  model.lowerPositionLimit[entries(joints[1]).first] = -std::numeric_limits<double>::max();
  model.upperPositionLimit[entries(joints[1]).first] = 2.;
  BOOST_CHECK(pinsettle::JointStops(model).unappliedLimitJoints() == expected);
  BOOST_CHECK(pinsettle::JointStops(model, false).unappliedLimitJoints().empty());
}

BOOST_AUTO_TEST_CASE(set_limit_checks_its_input)
{
  const pinocchio::Model model = chain(2);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(2, -1., 1.);
  stops.setLimit(1, 0.2, kInf);
  BOOST_REQUIRE_EQUAL(stops.stops().size(), 2u);
  BOOST_CHECK_EQUAL(stops.stops()[0].joint, 1u); // kept in joint order
  stops.setLimit(2, -2., 2.);                    // overrides
  BOOST_CHECK_EQUAL(stops.stops().size(), 2u);
  BOOST_CHECK_EQUAL(stops.stops()[1].lower, -2.);
  stops.removeLimit(1);
  BOOST_CHECK_EQUAL(stops.stops().size(), 1u);
  BOOST_CHECK_THROW(stops.setLimit(2, 1., -1.), std::invalid_argument);
  BOOST_CHECK_THROW(stops.setLimit(0, -1., 1.), std::invalid_argument);
  BOOST_CHECK_THROW(stops.setLimit(2, std::nan(""), 1.), std::invalid_argument);
  pinocchio::Model ball;
  ball.addJoint(0, pinocchio::JointModelSpherical(), pinocchio::SE3::Identity(), "ball");
  pinsettle::JointStops none(ball, false);
  try
  {
    none.setLimit(1, -1., 1.);
    BOOST_ERROR("a stop on a spherical joint was accepted");
  }
  catch (const std::invalid_argument & e)
  {
    BOOST_CHECK(std::string(e.what()).find("'ball'") != std::string::npos);
  }
}

BOOST_AUTO_TEST_CASE(an_impact_is_inelastic_and_clamping_reports_the_move)
{
  const pinocchio::Model model = chain(2);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, -0.5, 0.5);
  Eigen::VectorXd q(2), v(2);
  q << 0.7, 3.;
  v << 2., -1.;
  BOOST_CHECK(pinsettle::enforceStops(stops, q, v));
  BOOST_CHECK_EQUAL(q[0], 0.5);
  BOOST_CHECK_EQUAL(v[0], 0.);  // the velocity into the stop is gone
  BOOST_CHECK_EQUAL(v[1], -1.); // other joints untouched
  v[0] = -0.3;                  // moving off the stop is allowed
  BOOST_CHECK(!pinsettle::enforceStops(stops, q, v));
  BOOST_CHECK_EQUAL(v[0], -0.3);

  std::vector<std::pair<pinocchio::JointIndex, double>> moved;
  q << -0.9, 0.;
  BOOST_CHECK_CLOSE(pinsettle::clampToStops(stops, q, &moved), 0.4, 1e-12);
  BOOST_REQUIRE_EQUAL(moved.size(), 1u);
  BOOST_CHECK_EQUAL(moved[0].first, 1u);
  BOOST_CHECK_EQUAL(q[0], -0.5);
}

BOOST_AUTO_TEST_CASE(contacts_and_residual_follow_the_conditions_of_a_rest)
{
  const pinocchio::Model model = chain(3);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, -0.5, 0.5);
  stops.setLimit(2, -0.5, 0.5);
  Eigen::VectorXd q(3), tau(3);
  q << -0.5, 0.5, 0.1;
  tau << 2., 3., -0.25;
  // j1 on its lower stop pressed into it (tau >= 0): reaction 2; j2 on its upper stop pulled
  // off it (tau > 0): reaction 0, violation 3; j3 free: violation 0.25.
  const std::vector<pinsettle::StopContact> contacts =
    pinsettle::computeStopContacts(stops, q, tau);
  BOOST_REQUIRE_EQUAL(contacts.size(), 2u);
  BOOST_CHECK(contacts[0].side == pinsettle::StopSide::Lower);
  BOOST_CHECK_EQUAL(contacts[0].reaction, 2.);
  BOOST_CHECK(contacts[1].side == pinsettle::StopSide::Upper);
  BOOST_CHECK_EQUAL(contacts[1].reaction, 0.);
  BOOST_CHECK_EQUAL(pinsettle::computeStopResidual(stops, q, tau), 3.);
  tau[1] = -3.;
  BOOST_CHECK_EQUAL(pinsettle::computeStopResidual(stops, q, tau), 0.25);
  // Free directions: j1 and j2 are held (positive reactions), j3 is free.
  const Eigen::MatrixXd B = pinsettle::computeFreeDirections(stops, q, tau, 1e-9);
  BOOST_REQUIRE_EQUAL(B.cols(), 1);
  BOOST_CHECK_EQUAL(B(2, 0), 1.);
}

BOOST_AUTO_TEST_CASE(held_acceleration_is_that_of_the_joint_locked)
{
  // j1 on its lower stop, gravity pulling it down into the stop: the held acceleration of the
  // others is that of the chain with j1 locked, M_ff a_f = f_f.
  const pinocchio::Model model = chain(3);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, 0.4, kInf);
  pinocchio::Data data(model), ref(model);
  Eigen::VectorXd q(3), v(3);
  q << 0.4, -0.3, 0.2;
  v << 0., 0.5, -0.2;
  pinsettle::prebuilt::aba(model, data, q, v, Eigen::VectorXd::Zero(3));
  BOOST_REQUIRE_LT(data.ddq[0], 0.); // falls into the stop
  const Eigen::VectorXd free_motion = data.ddq;
  pinsettle::StopHold hold(stops);
  BOOST_CHECK(hold.hold(data, q, v, nullptr));
  pinsettle::prebuilt::crba(model, ref, q);
  const Eigen::MatrixXd M = ref.M.selfadjointView<Eigen::Upper>();
  const Eigen::VectorXd f = M * free_motion;
  const Eigen::Vector2d expected = M.bottomRightCorner(2, 2).llt().solve(f.tail(2));
  BOOST_CHECK_EQUAL(data.ddq[0], 0.);
  BOOST_CHECK(data.ddq.tail(2).isApprox(expected, 1e-12));
  // Its stop pushes: (M a - f)_1 > 0 at a lower stop.
  BOOST_CHECK_GT((M * data.ddq - f)[0], 0.);

  // Moving off the stop, or accelerating away from it, the joint is not held.
  v[0] = 0.1;
  pinsettle::prebuilt::aba(model, data, q, v, Eigen::VectorXd::Zero(3));
  BOOST_CHECK(!hold.hold(data, q, v, nullptr));
  q[0] = 0.4 + 1e-9;
  v[0] = 0.;
  pinsettle::prebuilt::aba(model, data, q, v, Eigen::VectorXd::Zero(3));
  BOOST_CHECK(!hold.hold(data, q, v, nullptr));
}

BOOST_AUTO_TEST_CASE(a_pendulum_comes_to_rest_on_its_stop)
{
  // Hanging would be q = 0; the stop at 0.5 holds it with reaction m g (l/2) sin(0.5).
  const double m = 2., l = 0.8, g = 9.81;
  const pinocchio::Model model = chain(1, m, l);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, 0.5, 1.5);
  pinsettle::Solver solver(model, nullptr, &stops);
  for (const double kt : {0., 0.5})
  {
    pinsettle::Settings settings;
    settings.kt = kt;
    const pinsettle::Result result = solver.solve(Eigen::VectorXd::Constant(1, 1.4), settings);
    BOOST_CHECK(result.status == pinsettle::Status::Converged);
    BOOST_CHECK_EQUAL(result.q[0], 0.5);
    BOOST_REQUIRE_EQUAL(result.stop_contacts.size(), 1u);
    BOOST_CHECK(result.stop_contacts[0].side == pinsettle::StopSide::Lower);
    BOOST_CHECK_CLOSE(result.stop_contacts[0].reaction, m * g * 0.5 * l * std::sin(0.5), 1e-9);
    BOOST_CHECK_EQUAL(result.residual, 0.);
    BOOST_CHECK(result.stability == pinsettle::Stability::Stable);
    BOOST_CHECK_EQUAL(restViolation(model, stops, result.q), 0.);
  }
  // A start outside the range is moved onto the nearest stop and reported.
  const pinsettle::Result clamped = solver.solve(Eigen::VectorXd::Constant(1, 2.));
  BOOST_REQUIRE_EQUAL(clamped.info.start_clamped.size(), 1u);
  BOOST_CHECK_CLOSE(clamped.info.start_clamped[0].second, 0.5, 1e-12);
  BOOST_CHECK(clamped.status == pinsettle::Status::Converged);
}

BOOST_AUTO_TEST_CASE(a_chain_rests_with_one_joint_on_a_stop_and_the_rest_free)
{
  // The first link cannot reach the vertical (stop at 0.6); the links below it hang straight
  // down: their absolute angle is 0, so j2 = -0.6 and j3 = 0.
  const pinocchio::Model model = chain(3);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, 0.6, 2.);
  pinsettle::Solver solver(model, nullptr, &stops);
  pinsettle::Settings settings;
  settings.polish = true;
  Eigen::VectorXd q0(3);
  q0 << 1.5, 0.5, -0.5;
  const pinsettle::Result result = solver.solve(q0, settings);
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  BOOST_CHECK_EQUAL(result.q[0], 0.6);
  BOOST_CHECK_SMALL(result.q[1] + 0.6, 1e-9);
  BOOST_CHECK_SMALL(result.q[2], 1e-9);
  BOOST_CHECK_LT(restViolation(model, stops, result.q), 1e-9);
  BOOST_CHECK(result.stability == pinsettle::Stability::Stable);
  BOOST_CHECK_EQUAL(result.stop_contacts.size(), 1u);
}

BOOST_AUTO_TEST_CASE(joint_inertia_keeps_the_rest_on_a_stop_run_after_run)
{
  // The same chain with the fictitious joint inertia: the held and locked joints run on the
  // model that carries it. The rest's conditions hold without the polish, and a solver used
  // again runs as a fresh one does (to round-off: without the joint inertia too, a second run
  // ends within 1e-25 of a fresh solver's).
  const pinocchio::Model model = chain(3);
  pinsettle::JointStops stops(model, false);
  stops.setLimit(1, 0.6, 2.);
  pinsettle::Settings settings;
  settings.scale_joint_inertia = pinsettle::Toggle::On;
  settings.polish = false;
  settings.max_e = 1e-16;
  Eigen::VectorXd q0(3);
  q0 << 1.5, 0.5, -0.5;
  pinsettle::Solver solver(model, nullptr, &stops);
  const pinsettle::Result first = solver.solve(q0, settings);
  const pinsettle::Result second = solver.solve(q0, settings);
  const pinsettle::Result fresh = pinsettle::Solver(model, nullptr, &stops).solve(q0, settings);
  BOOST_REQUIRE(first.status == pinsettle::Status::Converged);
  BOOST_CHECK_GT(first.info.scaled_joints, 0);
  BOOST_CHECK_EQUAL(first.q[0], 0.6);
  BOOST_CHECK_LT(restViolation(model, stops, first.q), 1e-6);
  BOOST_CHECK(first.stability == pinsettle::Stability::Stable);
  BOOST_CHECK_EQUAL(second.info.steps, fresh.info.steps);
  BOOST_CHECK_LT((second.q - fresh.q).lpNorm<Eigen::Infinity>(), 1e-12);
  BOOST_CHECK_EQUAL((first.q - fresh.q).lpNorm<Eigen::Infinity>(), 0.);
}

BOOST_AUTO_TEST_CASE(robots_released_from_neutral_rest_inside_their_limits)
{
  // Arms of example-robot-data that pass through their stops without them.
  for (const char * urdf :
       {"/xarm_description/urdf/xarm7.urdf", "/kinova_description/robots/kinova.urdf",
        "/so_arm_description/urdf/so101.urdf", "/panda_description/urdf/panda.urdf"})
  {
    const pinocchio::Model model = pinsettle::buildModelFromUrdf(robots_dir + urdf);
    const pinsettle::JointStops stops(model);
    BOOST_REQUIRE(!stops.empty());
    pinsettle::Solver solver(model, nullptr, &stops);
    pinsettle::Settings settings;
    settings.max_time = 30.;
    const pinsettle::Result result = solver.solve(pinocchio::neutral(model), settings);
    BOOST_TEST_CONTEXT(urdf)
    {
      BOOST_CHECK(result.status == pinsettle::Status::Converged);
      BOOST_CHECK(result.stability != pinsettle::Stability::Unstable);
      BOOST_CHECK_LT(restViolation(model, stops, result.q), 1e-4);
      BOOST_CHECK_LE(result.residual, restViolation(model, stops, result.q) * (1. + 1e-9) + 1e-12);
    }
  }
}

BOOST_AUTO_TEST_CASE(no_stop_no_change)
{
  // Stops that are never reached leave the trajectory as it is without them.
  const pinocchio::Model model = chain(3);
  pinsettle::JointStops far(model, false);
  far.setLimit(2, -3., 3.);
  Eigen::VectorXd q0(3);
  q0 << 1., -0.5, 0.3;
  pinsettle::Solver with(model, nullptr, &far), without(model);
  const pinsettle::Result a = with.solve(q0), b = without.solve(q0);
  BOOST_CHECK_EQUAL(a.info.steps, b.info.steps);
  BOOST_CHECK(a.q == b.q);
  BOOST_CHECK(a.stop_contacts.empty());
  // Stops and loops together are accepted (tests/test_limits.py checks a four-bar on a stop
  // against its closed form).
  pinsettle::LoopConstraints loops(model);
  loops.addLoop(
    model.getFrameId("j3"), Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0., 0., -1.),
    pinsettle::LoopKind::Point);
  BOOST_CHECK_NO_THROW(pinsettle::Solver(model, &loops, &far));
}
