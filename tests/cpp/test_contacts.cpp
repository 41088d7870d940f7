//
// Boost.Test cases of ground contacts: the contact Jacobian against finite differences of the
// contact point and the gap, the impulse solve against Coulomb's conditions, a step's impulses
// against a closed form (a rod landing on one end), and a box resting on a floor checked with
// Pinocchio's own functions (not the solver's balance).
//

#define BOOST_TEST_MODULE pinsettle_contacts
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
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

  // A uniform box (kg; m along x, y, z) on a free-flyer, its centre at the joint's origin.
  pinocchio::Model freeBox(double mass, double x, double y, double z)
  {
    pinocchio::Model model;
    const auto root =
      model.addJoint(0, pinocchio::JointModelFreeFlyer(), pinocchio::SE3::Identity(), "root");
    model.appendBodyToJoint(
      root, pinocchio::Inertia::FromBox(mass, x, y, z), pinocchio::SE3::Identity());
    return model;
  }
} // namespace

BOOST_AUTO_TEST_CASE(jacobian_rows_are_the_contact_velocity_and_the_gap_gradient)
{
  const pinocchio::Model model = boxWithArm();
  pinocchio::Data data(model);
  pinsettle::GroundContacts contacts(model);
  contacts.addPlane("slope", Eigen::Vector3d(0., 0., -0.3), Eigen::Vector3d(-0.3, 0.1, 1.), 0.6);
  // A turned box: the points meet its faces, edges and corners (and its inside) by turns.
  const Eigen::Matrix3d turn =
    Eigen::AngleAxisd(0.4, Eigen::Vector3d(1., 1., 0.).normalized()).toRotationMatrix();
  contacts.addBox(
    "block", Eigen::Vector3d(0.2, -0.1, -0.2), turn, Eigen::Vector3d(0.3, 0.2, 0.1), 0.5);
  contacts.addPoint("tip", 2, Eigen::Vector3d(0.02, 0.01, -0.2), 0.03);
  contacts.addPoint("corner", 1, Eigen::Vector3d(-0.1, 0.05, -0.05), 0.);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 20; ++trial)
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
      const pinsettle::GroundContacts::Point & s = contacts.pointOf(p);
      const auto axes = at.axes.middleCols<3>(3 * p);
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
      for (int r = 0; r < 3; ++r)
        BOOST_CHECK_SMALL(at.jacobian.row(3 * p + r).dot(v) - axes.col(r).dot(velocity), 1e-7);
      // The axes are a right-handed orthonormal frame.
      BOOST_CHECK_SMALL((axes.transpose() * axes - Eigen::Matrix3d::Identity()).norm(), 1e-12);
      BOOST_CHECK_CLOSE(axes.determinant(), 1., 1e-10);
    }
  }
}

BOOST_AUTO_TEST_CASE(a_sphere_touches_a_box_at_its_face_edge_corner_and_from_inside)
{
  const pinocchio::Model model = boxWithArm();
  pinsettle::GroundContacts contacts(model);
  // A 2 x 1 x 0.4 m box, centred at (1, 0, 0), turned a quarter about z: its x is the world's y.
  const Eigen::Matrix3d quarter = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).matrix();
  contacts.addBox("b", Eigen::Vector3d(1., 0., 0.), quarter, Eigen::Vector3d(1., 0.5, 0.2), 0.5);
  const pinsettle::GroundContacts::Ground & box = contacts.grounds()[0];
  double gap = 0.;
  Eigen::Vector3d point;
  Eigen::Matrix3d axes;
  struct Case
  {
    Eigen::Vector3d centre;
    double gap;
    Eigen::Vector3d normal;
  };
  const double d = std::sqrt(0.5);
  const Case cases[] = {
    {{1.1, 0.3, 0.5}, 0.3 - 0.05, {0., 0., 1.}},              // over the top
    {{1.7, 0.0, 0.}, 0.2 - 0.05, {1., 0., 0.}},               // beside a long face
    {{1.5 + 0.3, 1.0 + 0.3, 0.}, 0.3 / d - 0.05, {d, d, 0.}}, // off a vertical edge
    {{1.5 + 0.1, -1. - 0.2, -0.2 - 0.2}, 0.3 - 0.05, {1. / 3, -2. / 3, -2. / 3}}, // a corner
    {{1.0, 0.9, 0.}, -0.1 - 0.05, {0., 1., 0.}}, // inside, near an end
  };
  for (const Case & c : cases)
  {
    pinsettle::touchGround(box, c.centre, 0.05, gap, point, axes);
    BOOST_CHECK_CLOSE(gap, c.gap, 1e-9);
    BOOST_CHECK_SMALL((axes.col(2) - c.normal).norm(), 1e-12);
    BOOST_CHECK_SMALL((point - (c.centre - 0.05 * c.normal)).norm(), 1e-12);
  }
  BOOST_CHECK_THROW(
    contacts.addBox("flat", Eigen::Vector3d::Zero(), quarter, Eigen::Vector3d(1., 0., 1.), 0.5),
    std::invalid_argument);
  BOOST_CHECK_THROW(
    contacts.addBox("skew", Eigen::Vector3d::Zero(), 2. * quarter, Eigen::Vector3d::Ones(), 0.5),
    std::invalid_argument);
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
    const Eigen::MatrixXd Y = A.transpose() / std::sqrt(12.);
    const Eigen::MatrixXd G = Y.transpose() * Y;
    Eigen::VectorXd b(10), mu(3), lambda = Eigen::VectorXd::Zero(10);
    for (Eigen::Index k = 0; k < 10; ++k)
      b[k] = normal(rng);
    for (Eigen::Index k = 0; k < 3; ++k)
      mu[k] = 0.2 + 0.3 * k;
    pinsettle::ImpulseWorkspace work;
    pinsettle::solveContactImpulses(Y, b, mu, lambda, work);
    BOOST_CHECK_SMALL((work.w - Y * lambda).lpNorm<Eigen::Infinity>(), 1e-12);
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
  const pinocchio::Model model = freeBox(2., 0.2, 0.1, 0.1);
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

BOOST_AUTO_TEST_CASE(a_step_holds_the_pairs_its_impulses_close)
{
  // A rod (1 kg, 1 m) falling at 1 m/s and turning at 4 rad/s, both ends 0.1 mm above a floor:
  // its left end comes down at 3 m/s and closes, its right end goes up at 1 m/s. The left end's
  // inelastic impulse turns the rod the other way: the right end then comes down at about
  // 0.5 m/s (v_right + v_left / 2 for a uniform rod) and would sink 5 mm in a 10 ms step.
  const pinocchio::Model model = freeBox(1., 1., 0.01, 0.01);
  pinsettle::GroundContacts contacts(model);
  contacts.addPlane("floor", Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 0.5);
  contacts.addPoint("left", 1, Eigen::Vector3d(-0.5, 0., 0.), 0.);
  contacts.addPoint("right", 1, Eigen::Vector3d(0.5, 0., 0.), 0.);
  Eigen::VectorXd q = pinocchio::neutral(model);
  q[2] = 1e-4;
  Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
  v[2] = -1.;
  v[4] = -4.;
  const double h = 0.01;
  pinocchio::Data data(model);
  Eigen::VectorXd ddq = pinocchio::aba(model, data, q, v, Eigen::VectorXd::Zero(model.nv));
  const Eigen::VectorXd v_free = v + h * ddq;
  pinsettle::ContactStepper stepper(contacts, nullptr);
  stepper.start();
  stepper.apply(model, data, q, v, ddq, h);
  const Eigen::VectorXd v_next = v + h * ddq;
  pinsettle::ContactGeometry geometry;
  pinsettle::computeContactGeometry(model, data, contacts, q, geometry);
  for (int p = 0; p < 2; ++p)
  {
    const double un = geometry.jacobian.row(3 * p + 2).dot(v_next);
    BOOST_CHECK_GE(geometry.gap[p] + h * un, -1e-9);   // sinks into the floor by nothing
    BOOST_CHECK_SMALL(geometry.gap[p] + h * un, 1e-9); // both ends land
  }
  // The right end went up before the impulses: a step that held only the pairs closing at the
  // free velocity would have let it sink.
  BOOST_CHECK_GT(geometry.jacobian.row(5).dot(v_free), 0.5);
  // Inelastic, nothing sunk in: the impulses take kinetic energy out.
  pinocchio::crba(model, data, q);
  data.M.triangularView<Eigen::StrictlyLower>() = data.M.transpose();
  BOOST_CHECK_LT(v_next.dot(data.M * v_next), v_free.dot(data.M * v_free));
}
