//
// Boost.Test cases of ground contacts: the contact Jacobian against finite differences of the
// contact point and the gap, the impulse solve against Coulomb's conditions, and a box resting
// on a floor checked with Pinocchio's own functions (not the solver's balance).
//

#define BOOST_TEST_MODULE pinsettle_contacts
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <cmath>
#include <random>

namespace
{
  // A floating box (1 kg, 0.2 x 0.1 x 0.1 m) under a revolute arm: two bodies, seven joints'
  // worth of velocity, so that the Jacobian of a point on the arm runs through both.
  pinocchio::Model boxWithArm()
  {
    pinocchio::Model model;
    const auto root =
      model.addJoint(0, pinocchio::JointModelFreeFlyer(), pinocchio::SE3::Identity(), "root");
    model.appendBodyToJoint(
      root, pinocchio::Inertia::FromBox(1., 0.2, 0.1, 0.1), pinocchio::SE3::Identity());
    const pinocchio::SE3 at(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.1, 0., -0.05));
    const auto arm = model.addJoint(root, pinocchio::JointModelRY(), at, "arm");
    model.appendBodyToJoint(
      arm,
      pinocchio::Inertia(0.2, Eigen::Vector3d(0., 0., -0.1), Eigen::Matrix3d::Identity() * 1e-3),
      pinocchio::SE3::Identity());
    return model;
  }
} // namespace

BOOST_AUTO_TEST_CASE(jacobian_rows_are_the_contact_velocity_and_the_gap_gradient)
{
  const pinocchio::Model model = boxWithArm();
  pinocchio::Data data(model);
  pinsettle::GroundContacts contacts(model);
  contacts.addPlane("slope", Eigen::Vector3d(0., 0., -0.3), Eigen::Vector3d(-0.3, 0.1, 1.), 0.6);
  contacts.addPoint("tip", 2, Eigen::Vector3d(0.02, 0.01, -0.2), 0.03);
  contacts.addPoint("corner", 1, Eigen::Vector3d(-0.1, 0.05, -0.05), 0.);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 5; ++trial)
  {
    Eigen::VectorXd q = pinocchio::randomConfiguration(
      model, -Eigen::VectorXd::Ones(model.nq), Eigen::VectorXd::Ones(model.nq));
    Eigen::VectorXd v(model.nv);
    for (Eigen::Index k = 0; k < v.size(); ++k)
      v[k] = normal(rng);
    pinsettle::ContactGeometry at, ahead, behind;
    pinsettle::computeContactGeometry(model, data, contacts, q, at);
    const double h = 1e-6;
    Eigen::VectorXd q_plus(model.nq), q_minus(model.nq);
    pinocchio::integrate(model, q, (h * v).eval(), q_plus);
    pinocchio::integrate(model, q, (-h * v).eval(), q_minus);
    pinsettle::computeContactGeometry(model, data, contacts, q_plus, ahead);
    pinsettle::computeContactGeometry(model, data, contacts, q_minus, behind);
    for (int p = 0; p < contacts.pairs(); ++p)
    {
      const pinsettle::GroundContacts::Plane & plane = contacts.planes()[0];
      const pinsettle::GroundContacts::Point & s = contacts.points()[static_cast<std::size_t>(p)];
      // The normal row is the gap's gradient.
      const double dgap = (ahead.gap[p] - behind.gap[p]) / (2. * h);
      BOOST_CHECK_SMALL(at.jacobian.row(3 * p + 2).dot(v) - dgap, 1e-7);
      // The tangent rows: the velocity of the body's material point at the contact point,
      // moved with the body (recomputed with Pinocchio's placements).
      pinocchio::forwardKinematics(model, data, q);
      const Eigen::Vector3d local = data.oMi[s.joint].actInv(Eigen::Vector3d(at.point.col(p)));
      pinocchio::forwardKinematics(model, data, q_plus);
      const Eigen::Vector3d x_plus = data.oMi[s.joint].act(local);
      pinocchio::forwardKinematics(model, data, q_minus);
      const Eigen::Vector3d x_minus = data.oMi[s.joint].act(local);
      const Eigen::Vector3d velocity = (x_plus - x_minus) / (2. * h);
      BOOST_CHECK_SMALL(at.jacobian.row(3 * p).dot(v) - plane.t1.dot(velocity), 1e-7);
      BOOST_CHECK_SMALL(at.jacobian.row(3 * p + 1).dot(v) - plane.t2.dot(velocity), 1e-7);
      BOOST_CHECK_SMALL(at.jacobian.row(3 * p + 2).dot(v) - plane.normal.dot(velocity), 1e-7);
    }
  }
}

BOOST_AUTO_TEST_CASE(impulses_meet_coulombs_conditions)
{
  // Random Delassus matrices of three contacts and one stop row: each answer pressing, in its
  // cone, complementary to its velocity; sticking where the cone's inside, sliding against the
  // motion at its edge.
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 20; ++trial)
  {
    Eigen::MatrixXd A(10, 12);
    for (Eigen::Index i = 0; i < A.rows(); ++i)
      for (Eigen::Index j = 0; j < A.cols(); ++j)
        A(i, j) = normal(rng);
    const Eigen::MatrixXd G = A * A.transpose() / 12.;
    Eigen::VectorXd b(10), mu(3), lambda = Eigen::VectorXd::Zero(10);
    for (Eigen::Index k = 0; k < 10; ++k)
      b[k] = normal(rng);
    for (Eigen::Index k = 0; k < 3; ++k)
      mu[k] = 0.2 + 0.3 * k;
    pinsettle::solveContactImpulses(G, b, mu, lambda);
    const Eigen::VectorXd u = G * lambda + b;
    const double scale = 1e-6 * (1. + lambda.lpNorm<Eigen::Infinity>());
    for (Eigen::Index k = 0; k < 3; ++k)
    {
      const double ln = lambda[3 * k + 2], un = u[3 * k + 2];
      const Eigen::Vector2d lt = lambda.segment<2>(3 * k), ut = u.segment<2>(3 * k);
      BOOST_CHECK_GE(ln, 0.);
      BOOST_CHECK_GE(un, -scale);
      BOOST_CHECK_SMALL(ln * un, scale);
      BOOST_CHECK_LE(lt.norm(), mu[k] * ln + 1e-12);
      if (lt.norm() < mu[k] * ln * (1. - 1e-6))
        BOOST_CHECK_SMALL(ut.norm(), scale);
      else if (ut.norm() > scale)
        BOOST_CHECK_SMALL((lt + mu[k] * ln * ut.normalized()).norm(), scale);
    }
    BOOST_CHECK_GE(lambda[9], 0.);
    BOOST_CHECK_GE(u[9], -scale);
    BOOST_CHECK_SMALL(lambda[9] * u[9], scale);
  }
}

BOOST_AUTO_TEST_CASE(a_box_rests_on_a_floor_on_its_four_corners)
{
  pinocchio::Model model;
  const auto root =
    model.addJoint(0, pinocchio::JointModelFreeFlyer(), pinocchio::SE3::Identity(), "root");
  model.appendBodyToJoint(
    root, pinocchio::Inertia::FromBox(2., 0.2, 0.1, 0.1), pinocchio::SE3::Identity());
  pinsettle::GroundContacts contacts(model);
  contacts.addPlane("floor", Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 0.5);
  for (const double x : {-0.1, 0.1})
    for (const double y : {-0.05, 0.05})
      contacts.addPoint("corner", 1, Eigen::Vector3d(x, y, -0.05), 0.);
  pinsettle::Solver solver(model, nullptr, nullptr, &contacts);
  Eigen::VectorXd q0 = pinocchio::neutral(model);
  q0[2] = 0.2;
  const pinsettle::Result result = solver.solve(q0, pinsettle::Settings());
  BOOST_REQUIRE(result.status == pinsettle::Status::Converged);
  BOOST_CHECK(result.stability == pinsettle::Stability::Stable);
  BOOST_CHECK_CLOSE(result.q[2], 0.05, 1e-4);
  // Each corner carries m g / 4; together they balance gravity (rnea at rest).
  BOOST_REQUIRE_EQUAL(result.ground_contacts.size(), 4u);
  pinocchio::Data data(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
  const Eigen::VectorXd g = pinocchio::rnea(model, data, result.q, zero, zero);
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  for (const pinsettle::GroundContact & c : result.ground_contacts)
  {
    BOOST_CHECK_CLOSE(c.normal_force, 2. * 9.81 / 4., 1e-7);
    BOOST_CHECK_SMALL(c.tangential_force.norm(), 1e-9);
    BOOST_CHECK_SMALL(c.gap, 1e-9);
    total += c.normal_force * c.normal + c.tangential_force;
  }
  // The root's linear force, in its local frame at rest level: the total lifts the weight.
  BOOST_CHECK_SMALL((data.oMi[1].rotation() * g.head<3>() - total).norm(), 1e-9);
}
