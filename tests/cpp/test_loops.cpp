//
// Copyright (c) 2026 pinsettle contributors
//
// Loop closures: Jacobians against finite differences, assembly, the constrained solve, and the
// reduced stiffness against a second route (finite differences along the projected path).
//

#define BOOST_TEST_MODULE pinsettle_loops
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace
{
  const std::string robots_dir = PINSETTLE_ROBOTS_DIR;

  // A rod of mass m and length l along the joint's x axis.
  pinocchio::Inertia rod(double m, double l)
  {
    return pinocchio::Inertia(
      m, Eigen::Vector3d(0.5 * l, 0., 0.),
      Eigen::Vector3d(1e-5, m * l * l / 12., m * l * l / 12.).asDiagonal());
  }

  // A four-bar in the x-z plane, hinges about y: crank (0.15 m) at the origin, coupler (0.4 m)
  // on the crank, rocker (0.3 m) at (0.4, 0, 0); the loop joins the coupler's end to the
  // rocker's. Frames "coupler_end" and "rocker_end" sit at those ends.
  pinocchio::Model fourBar()
  {
    pinocchio::Model model;
    const auto crank =
      model.addJoint(0, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "crank");
    model.appendBodyToJoint(crank, rod(0.5, 0.15));
    const auto coupler = model.addJoint(
      crank, pinocchio::JointModelRY(),
      pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.15, 0., 0.)), "coupler");
    model.appendBodyToJoint(coupler, rod(1.0, 0.4));
    const auto rocker = model.addJoint(
      0, pinocchio::JointModelRY(),
      pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.4, 0., 0.)), "rocker");
    model.appendBodyToJoint(rocker, rod(0.8, 0.3));
    for (const auto & body :
         {std::make_pair("crank_body", crank), std::make_pair("coupler_body", coupler),
          std::make_pair("rocker_body", rocker)})
      model.addFrame(
        pinocchio::Frame(body.first, body.second, pinocchio::SE3::Identity(), pinocchio::OP_FRAME));
    return model;
  }

  pinsettle::LoopConstraints fourBarLoop(const pinocchio::Model & model)
  {
    pinsettle::LoopConstraints loops(model);
    loops.addLoop(
      model.getFrameId("coupler_body"), Eigen::Vector3d(0.4, 0., 0.),
      model.getFrameId("rocker_body"), Eigen::Vector3d(0.3, 0., 0.), pinsettle::LoopKind::Point);
    return loops;
  }

  Eigen::VectorXd fourBarStart()
  {
    Eigen::VectorXd q(3);
    q << -1.0, 0.8, -1.6;
    return q;
  }

  // Finite-difference Jacobian of the loop errors along the tangent directions.
  Eigen::MatrixXd fdJacobian(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const Eigen::VectorXd & q,
    double h = 1e-7)
  {
    pinocchio::Data data(model);
    Eigen::MatrixXd J(loops.rows(), model.nv);
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv), qp(model.nq), qm(model.nq);
    for (int k = 0; k < model.nv; ++k)
    {
      dq[k] = h;
      pinocchio::integrate(model, q, dq, qp);
      pinocchio::integrate(model, q, -dq, qm);
      dq[k] = 0.;
      J.col(k) = (pinsettle::computeLoopError(model, data, loops, qp)
                  - pinsettle::computeLoopError(model, data, loops, qm))
                 / (2. * h);
    }
    return J;
  }
} // namespace

BOOST_AUTO_TEST_CASE(point_loop_jacobian_matches_finite_differences_on_a_spatial_arm)
{
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  pinocchio::Data data(model);
  pinsettle::LoopConstraints loops(model);
  loops.addLoop(
    model.getFrameId("tool0"), Eigen::Vector3d(0.01, 0.02, 0.03),
    model.getFrameId("upper_arm_link"), Eigen::Vector3d(0.1, -0.05, 0.2));
  loops.addLoop(
    model.getFrameId("forearm_link"), Eigen::Vector3d(0.0, 0.1, 0.0), 0,
    Eigen::Vector3d(0.3, 0.2, 0.1));
  BOOST_CHECK_EQUAL(loops.rows(), 6);
  std::srand(3);
  for (int trial = 0; trial < 10; ++trial)
  {
    const Eigen::VectorXd q = pinocchio::randomConfiguration(model);
    const Eigen::MatrixXd J = pinsettle::computeLoopJacobian(model, data, loops, q);
    const Eigen::MatrixXd fd = fdJacobian(model, loops, q);
    BOOST_CHECK_SMALL((J - fd).lpNorm<Eigen::Infinity>(), 1e-7);
  }
}

BOOST_AUTO_TEST_CASE(frame_loop_jacobian_matches_finite_differences_where_the_weld_holds)
{
  // A planar chain welded to the world at its fifth link's frame; the rotation rows are the
  // derivative of the rotation error where the two frames line up (on the constraint).
  const pinocchio::Model model =
    pinsettle::buildModelFromUrdf(std::string(PINSETTLE_REPO_ROBOTS_DIR) + "/chain20.urdf");
  pinocchio::Data data(model);
  Eigen::VectorXd q = Eigen::VectorXd::Random(model.nq) * 0.5;
  q[4] = -(q[0] + q[1] + q[2] + q[3]); // link5 level with the world: rotations agree
  pinocchio::forwardKinematics(model, data, q);
  const pinocchio::FrameIndex link5 = model.getFrameId("link5");
  pinocchio::updateFramePlacements(model, data);
  const Eigen::Vector3d where = data.oMf[link5].translation();
  pinsettle::LoopConstraints loops(model);
  loops.addLoop(link5, Eigen::Vector3d::Zero(), 0, where, pinsettle::LoopKind::Frame);
  BOOST_CHECK_SMALL(
    pinsettle::computeLoopError(model, data, loops, q).lpNorm<Eigen::Infinity>(), 1e-12);
  const Eigen::MatrixXd J = pinsettle::computeLoopJacobian(model, data, loops, q);
  BOOST_CHECK_SMALL((J - fdJacobian(model, loops, q)).lpNorm<Eigen::Infinity>(), 1e-7);
  // Planar: of the 6 weld equations 3 are independent.
  const pinsettle::LoopMotion motion = pinsettle::computeLoopMotion(model, data, loops, q);
  BOOST_CHECK_EQUAL(motion.rank, 3);
  BOOST_CHECK_EQUAL(motion.basis.cols(), model.nv - 3);
  BOOST_CHECK_SMALL((J * motion.basis).lpNorm<Eigen::Infinity>(), 1e-12);
}

BOOST_AUTO_TEST_CASE(redundant_point_loop_assembles_and_settles)
{
  const pinocchio::Model model = fourBar();
  pinocchio::Data data(model);
  const pinsettle::LoopConstraints loops = fourBarLoop(model);
  Eigen::VectorXd q = fourBarStart();
  const double error_before = pinsettle::computeLoopError(model, data, loops, q).norm();
  BOOST_CHECK_GT(error_before, 1e-2);
  const double moved = pinsettle::assembleLoops(model, data, loops, q);
  BOOST_CHECK_GT(moved, 1e-3);
  BOOST_CHECK_SMALL(
    pinsettle::computeLoopError(model, data, loops, q).lpNorm<Eigen::Infinity>(), 1e-12);
  // The y row of a planar loop is redundant: rank 2 of 3, one degree of freedom.
  const pinsettle::LoopMotion motion = pinsettle::computeLoopMotion(model, data, loops, q);
  BOOST_CHECK_EQUAL(motion.rank, 2);
  BOOST_CHECK_EQUAL(motion.basis.cols(), 1);

  pinsettle::ForceElements springs(model);
  springs.addJointSpring(model.getJointId("crank"), 5., -1.);
  pinsettle::Solver solver(model, &loops);
  for (const pinsettle::EnergyMeasure energy :
       {pinsettle::EnergyMeasure::Exact, pinsettle::EnergyMeasure::Simplified})
  {
    pinsettle::Settings settings;
    settings.energy = energy;
    settings.polish = true;
    const pinsettle::Result r = solver.solve(fourBarStart(), settings, &springs);
    BOOST_CHECK(r.status == pinsettle::Status::Converged);
    BOOST_CHECK_EQUAL(r.info.mobility, 1);
    BOOST_CHECK_CLOSE(r.info.assembly_distance, moved, 1e-6);
    BOOST_CHECK_SMALL(r.constraint_error, 1e-10);
    BOOST_CHECK(r.stability == pinsettle::Stability::Stable);
    // The residual recomputed: the static force has no component along the allowed motion.
    const Eigen::VectorXd tau = pinsettle::computeStaticForce(model, data, r.q, &springs);
    const pinsettle::LoopMotion at = pinsettle::computeLoopMotion(model, data, loops, r.q);
    BOOST_CHECK_SMALL((at.basis.transpose() * tau).lpNorm<Eigen::Infinity>(), 1e-9);
    // ... while the tree alone is far from balanced: the loop carries load.
    BOOST_CHECK_GT(tau.lpNorm<Eigen::Infinity>(), 1e-2);
  }
}

BOOST_AUTO_TEST_CASE(reduced_stiffness_matches_the_projected_path)
{
  // K_r from the reactions held fixed (the library) against a second route: the static force
  // along the allowed motion, differenced along the path projected back onto the loop.
  const pinocchio::Model model = fourBar();
  pinocchio::Data data(model);
  const pinsettle::LoopConstraints loops = fourBarLoop(model);
  pinsettle::ForceElements springs(model);
  springs.addJointSpring(model.getJointId("crank"), 5., -1.);
  pinsettle::Settings settings;
  settings.polish = true;
  pinsettle::Solver solver(model, &loops);
  const pinsettle::Result r = solver.solve(fourBarStart(), settings, &springs);
  BOOST_REQUIRE(r.status == pinsettle::Status::Converged);
  const pinsettle::StabilityReport report =
    pinsettle::assessStability(model, data, loops, r.q, &springs);
  BOOST_REQUIRE_EQUAL(report.stiffness.rows(), 1);
  const Eigen::VectorXd n = report.basis.col(0);
  // The potential's slope along the path s -> q(s) = project(q* (+) s n), unit speed to O(s^2):
  // tau(q(s)) . t(s), t the allowed motion at q(s) oriented like n.
  const auto slope = [&](double s) {
    Eigen::VectorXd qs(model.nq);
    pinocchio::integrate(model, r.q, Eigen::VectorXd(s * n), qs);
    pinsettle::projectOntoLoops(model, data, loops, qs, 1e-15);
    Eigen::VectorXd t = pinsettle::computeLoopMotion(model, data, loops, qs).basis.col(0);
    if (t.dot(n) < 0.)
      t = -t;
    return pinsettle::computeStaticForce(model, data, qs, &springs).dot(t);
  };
  const double h = 1e-5;
  const double second_derivative = (slope(h) - slope(-h)) / (2. * h);
  BOOST_CHECK_GT(second_derivative, 0.1);
  BOOST_CHECK_CLOSE(report.stiffness(0, 0), second_derivative, 1e-4);
  // Without the loops' curvature term, N^T K N alone would be off: the term matters here.
  const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, data, r.q, &springs);
  BOOST_CHECK_GT(std::abs(n.dot(K * n) - second_derivative), 1e-2 * second_derivative);
}

BOOST_AUTO_TEST_CASE(empty_loops_step_exactly_like_the_tree)
{
  const pinocchio::Model model = fourBar();
  const pinsettle::LoopConstraints none(model);
  pinsettle::Solver plain(model), with_none(model, &none);
  Eigen::VectorXd q0(3);
  q0 << 0.3, -0.2, 0.5;
  const pinsettle::Result a = plain.solve(q0);
  const pinsettle::Result b = with_none.solve(q0);
  BOOST_CHECK_EQUAL(a.info.steps, b.info.steps);
  BOOST_CHECK((a.q.array() == b.q.array()).all());
  BOOST_CHECK_EQUAL(b.info.mobility, 3);
  BOOST_CHECK_EQUAL(b.constraint_error, 0.);
}

BOOST_AUTO_TEST_CASE(bad_loops_get_clear_errors)
{
  const pinocchio::Model model = fourBar();
  pinocchio::Data data(model);
  pinsettle::LoopConstraints loops(model);
  BOOST_CHECK_THROW(
    loops.addLoop(999, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d::Zero()), std::invalid_argument);
  BOOST_CHECK_THROW(
    loops.addLoop(
      model.getFrameId("coupler_body"), Eigen::Vector3d::Zero(), model.getFrameId("coupler_body"),
      Eigen::Vector3d(0.1, 0., 0.)),
    std::invalid_argument);
  // A coupler end that no pose brings to a point 2 m away: cannot be assembled.
  loops.addLoop(
    model.getFrameId("coupler_body"), Eigen::Vector3d(0.4, 0., 0.), 0, Eigen::Vector3d(2.0, 0., 0.),
    pinsettle::LoopKind::Point, "far loop");
  Eigen::VectorXd q = fourBarStart();
  const Eigen::VectorXd before = q;
  try
  {
    pinsettle::assembleLoops(model, data, loops, q);
    BOOST_ERROR("no error for a loop that cannot close");
  }
  catch (const std::invalid_argument & e)
  {
    const std::string msg = e.what();
    BOOST_CHECK(msg.find("far loop") != std::string::npos);
    BOOST_CHECK(msg.find("cannot assemble") != std::string::npos);
  }
  BOOST_CHECK((q.array() == before.array()).all());
  // The four-bar with its crank welded to the world is a structure: no motion left.
  pinsettle::LoopConstraints welded = fourBarLoop(model);
  welded.addLoop(
    model.getFrameId("crank_body"), Eigen::Vector3d::Zero(), 0, Eigen::Vector3d::Zero(),
    pinsettle::LoopKind::Frame);
  pinsettle::Solver solver(model, &welded);
  try
  {
    solver.solve(fourBarStart());
    BOOST_ERROR("no error for a mechanism without a degree of freedom");
  }
  catch (const std::invalid_argument & e)
  {
    BOOST_CHECK(std::string(e.what()).find("no degree of freedom") != std::string::npos);
  }
}
