//
// Copyright (c) 2026 pinsettle contributors
//
// Mimic joints: releaseMimicJoints gives the model without the coupling (checked against
// Pinocchio's own mimic model), and a joint coupling held as a constraint settles the coupled
// mechanism (checked against Pinocchio's rnea on the mimic model, the chain rule, and the
// curvature of the coupled potential), also together with a loop.
//

#define BOOST_TEST_MODULE pinsettle_mimic
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/model.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/SVD>

#include <cmath>
#include <stdexcept>
#include <string>

namespace
{
  constexpr double kMultiplier = -1.5, kOffset = 0.25;

  // Two links hanging from hinges about y, 0.5 m each; the second's mass off its axis.
  pinocchio::Model twoLinks()
  {
    pinocchio::Model model;
    const pinocchio::JointIndex j1 =
      model.addJoint(0, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "joint1");
    model.appendBodyToJoint(
      j1,
      pinocchio::Inertia(1., Eigen::Vector3d(0.05, 0., -0.25), Eigen::Matrix3d::Identity() * 1e-2));
    const pinocchio::JointIndex j2 = model.addJoint(
      j1, pinocchio::JointModelRY(),
      pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., -0.5)), "joint2");
    model.appendBodyToJoint(
      j2,
      pinocchio::Inertia(2., Eigen::Vector3d(0.1, 0., -0.3), Eigen::Matrix3d::Identity() * 2e-2));
    model.addFrame(pinocchio::Frame("tip", j2, pinocchio::SE3::Identity(), pinocchio::OP_FRAME));
    return model;
  }

  // joint2 follows joint1, as pinocchio.buildModelFromUrdf(path, mimic=True) makes of a tag.
  pinocchio::Model twoLinksWithMimic()
  {
    pinocchio::Model model;
    pinocchio::transformJointIntoMimic(twoLinks(), 1, 2, kMultiplier, kOffset, model);
    return model;
  }

  Eigen::VectorXd coupled(double theta)
  {
    Eigen::VectorXd q(2);
    q << theta, kMultiplier * theta + kOffset;
    return q;
  }

  // Potential energy of the coupled arm at leader angle theta (Pinocchio, free model).
  double potential(const pinocchio::Model & free, double theta)
  {
    pinocchio::Data data(free);
    return pinocchio::computePotentialEnergy(free, data, coupled(theta));
  }
} // namespace

BOOST_AUTO_TEST_CASE(released_model_is_the_free_model_with_the_coupling_returned)
{
  const pinocchio::Model mimic = twoLinksWithMimic();
  BOOST_REQUIRE_EQUAL(mimic.nq, 1);
  std::vector<pinsettle::MimicJoint> mimics;
  const pinocchio::Model released = pinsettle::releaseMimicJoints(mimic, mimics);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(released));
  BOOST_CHECK_THROW(pinsettle::checkSupportedModel(mimic), std::invalid_argument);
  BOOST_REQUIRE_EQUAL(mimics.size(), 1u);
  BOOST_CHECK_EQUAL(mimics[0].follower, 2u);
  BOOST_CHECK_EQUAL(mimics[0].leader, 1u);
  BOOST_CHECK_EQUAL(mimics[0].multiplier, kMultiplier);
  BOOST_CHECK_EQUAL(mimics[0].offset, kOffset);
  BOOST_CHECK_EQUAL(released.nq, 2);
  BOOST_CHECK_EQUAL(released.nv, 2);
  BOOST_CHECK_EQUAL(released.joints[2].shortname(), "JointModelRY");
  BOOST_CHECK_EQUAL(released.frames.size(), mimic.frames.size());
  BOOST_CHECK_EQUAL(released.getFrameId("tip"), mimic.getFrameId("tip"));
  // The follower keeps no limit (the mimic model has none for it); the leader keeps its own.
  BOOST_CHECK_GT(released.upperPositionLimit[1], 1e10);

  // Kinematics: the released model at (theta, m theta + offset) is the mimic model at theta.
  pinocchio::Data dm(mimic), dr(released);
  for (const double theta : {-1.2, 0.0, 0.7})
  {
    Eigen::VectorXd qm(1);
    qm << theta;
    pinocchio::forwardKinematics(mimic, dm, qm);
    pinocchio::forwardKinematics(released, dr, coupled(theta));
    for (pinocchio::JointIndex j = 1; j < 3; ++j)
      BOOST_CHECK(dm.oMi[j].isApprox(dr.oMi[j], 1e-12));
    // Pinocchio's rnea on the mimic model is the chain rule on the released one.
    const Eigen::VectorXd gm = pinocchio::computeGeneralizedGravity(mimic, dm, qm);
    const Eigen::VectorXd gr = pinocchio::computeGeneralizedGravity(released, dr, coupled(theta));
    BOOST_CHECK_SMALL(gm[0] - (gr[0] + kMultiplier * gr[1]), 1e-12);
  }
}

BOOST_AUTO_TEST_CASE(coupling_error_and_jacobian)
{
  const pinocchio::Model model = twoLinks();
  pinocchio::Data data(model);
  pinsettle::LoopConstraints couplings(model);
  couplings.addCoupling(2, 1, kMultiplier, kOffset, "mimic");
  BOOST_CHECK(!couplings.empty());
  BOOST_CHECK_EQUAL(couplings.rows(), 1);
  Eigen::VectorXd q(2);
  q << 0.4, 0.1;
  const Eigen::VectorXd e = pinsettle::computeLoopError(model, data, couplings, q);
  BOOST_CHECK_SMALL(e[0] - (0.1 - kMultiplier * 0.4 - kOffset), 1e-15);
  const Eigen::MatrixXd J = pinsettle::computeLoopJacobian(model, data, couplings, q);
  BOOST_CHECK_EQUAL(J(0, 0), -kMultiplier);
  BOOST_CHECK_EQUAL(J(0, 1), 1.);
  // Assembly moves q onto the coupling.
  pinsettle::assembleLoops(model, data, couplings, q);
  BOOST_CHECK_SMALL(pinsettle::computeLoopError(model, data, couplings, q)[0], 1e-12);
  BOOST_CHECK_EQUAL(pinsettle::computeLoopMotion(model, data, couplings, q).basis.cols(), 1);

  BOOST_CHECK_THROW(couplings.addCoupling(1, 1, 1., 0.), std::invalid_argument);
  BOOST_CHECK_THROW(couplings.addCoupling(3, 1, 1., 0.), std::invalid_argument);
  BOOST_CHECK_THROW(couplings.addCoupling(2, 1, NAN, 0.), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(solver_settles_the_coupled_arm_at_a_minimum_of_its_potential)
{
  std::vector<pinsettle::MimicJoint> mimics;
  const pinocchio::Model mimic = twoLinksWithMimic();
  const pinocchio::Model model = pinsettle::releaseMimicJoints(mimic, mimics);
  pinsettle::LoopConstraints couplings(model);
  for (const pinsettle::MimicJoint & m : mimics)
    couplings.addCoupling(m.follower, m.leader, m.multiplier, m.offset);
  pinsettle::Solver solver(model, &couplings);
  pinocchio::Data data(model), dm(mimic);
  for (const double start : {-2.0, 0.0, 0.4, 2.0})
  {
    Eigen::VectorXd q0(2);
    q0 << start, 0.; // off the coupling: assembled first
    const pinsettle::Result r = solver.solve(q0);
    BOOST_TEST_MESSAGE("start " << start << ": q " << r.q.transpose() << ", " << r.info.steps);
    BOOST_REQUIRE(r.status == pinsettle::Status::Converged);
    BOOST_CHECK_EQUAL(r.info.mobility, 1);
    BOOST_CHECK_SMALL(r.q[1] - (kMultiplier * r.q[0] + kOffset), 1e-12);
    // Pinocchio's rnea on the mimic model vanishes at the rest.
    Eigen::VectorXd qm(1);
    qm << r.q[0];
    BOOST_CHECK_SMALL(pinocchio::computeGeneralizedGravity(mimic, dm, qm)[0], 1e-8);
    // A minimum of the coupled potential, and the verdict says so.
    const double h = 1e-4;
    const double curvature =
      (potential(model, r.q[0] + h) - 2. * potential(model, r.q[0]) + potential(model, r.q[0] - h))
      / (h * h);
    BOOST_CHECK_GT(curvature, 0.);
    BOOST_CHECK(r.stability == pinsettle::Stability::Stable);
  }
}

namespace
{
  // A rod of mass m and length l along the joint's x axis.
  pinocchio::Inertia rod(double m, double l)
  {
    return pinocchio::Inertia(
      m, Eigen::Vector3d(0.5 * l, 0., 0.),
      Eigen::Vector3d(1e-5, m * l * l / 12., m * l * l / 12.).asDiagonal());
  }

  // The four-bar of test_loops.cpp (crank at the origin, coupler on it, rocker at (0.4, 0, 0),
  // hinges about y) and a pendulum at (-0.3, 0, 0) whose joint follows the crank.
  pinocchio::Model fourBarAndPendulum()
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
    const auto pendulum = model.addJoint(
      0, pinocchio::JointModelRY(),
      pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-0.3, 0., 0.)), "pendulum");
    model.appendBodyToJoint(pendulum, rod(0.7, 0.25));
    model.addFrame(
      pinocchio::Frame(
        "coupler_end", coupler,
        pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.4, 0., 0.)),
        pinocchio::OP_FRAME));
    model.addFrame(
      pinocchio::Frame(
        "rocker_end", rocker,
        pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.3, 0., 0.)),
        pinocchio::OP_FRAME));
    return model;
  }

  // The closure error from Pinocchio's frame placements (not pinsettle's loop code), and the
  // coupling pendulum = 0.5 crank + 0.3.
  Eigen::VectorXd closure(const pinocchio::Model & model, const Eigen::VectorXd & q)
  {
    pinocchio::Data data(model);
    pinocchio::framesForwardKinematics(model, data, q);
    Eigen::VectorXd e(4);
    e.head<3>() = data.oMf[model.getFrameId("coupler_end")].translation()
                  - data.oMf[model.getFrameId("rocker_end")].translation();
    e[3] = q[3] - 0.5 * q[0] - 0.3;
    return e;
  }
} // namespace

BOOST_AUTO_TEST_CASE(couplings_with_loops_settle_where_the_static_force_balances)
{
  const pinocchio::Model model = fourBarAndPendulum();
  pinsettle::LoopConstraints both(model);
  both.addLoop(
    model.getFrameId("coupler_end"), Eigen::Vector3d::Zero(), model.getFrameId("rocker_end"),
    Eigen::Vector3d::Zero());
  both.addCoupling(model.getJointId("pendulum"), model.getJointId("crank"), 0.5, 0.3);
  pinsettle::Solver solver(model, &both);
  Eigen::VectorXd q0(4);
  q0 << -1.0, 0.8, -1.6, -0.2;
  const pinsettle::Result r = solver.solve(q0);
  BOOST_TEST_MESSAGE("q " << r.q.transpose() << ", " << r.info.steps << " steps");
  BOOST_REQUIRE(r.status == pinsettle::Status::Converged);
  BOOST_CHECK_EQUAL(r.info.mobility, 1);
  // Independently: the constraints hold, and gravity has no component along the motion they
  // allow (the null space of their Jacobian by central differences of closure()).
  BOOST_CHECK_SMALL(closure(model, r.q).lpNorm<Eigen::Infinity>(), 1e-10);
  Eigen::MatrixXd J(4, 4);
  const double h = 1e-6;
  for (Eigen::Index k = 0; k < 4; ++k)
  {
    Eigen::VectorXd plus = r.q, minus = r.q;
    plus[k] += h;
    minus[k] -= h;
    J.col(k) = (closure(model, plus) - closure(model, minus)) / (2. * h);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullV);
  BOOST_REQUIRE_LT(svd.singularValues()[3], 1e-8 * svd.singularValues()[0]); // mobility 1
  BOOST_REQUIRE_GT(svd.singularValues()[2], 1e-3 * svd.singularValues()[0]);
  const Eigen::VectorXd motion = svd.matrixV().col(3);
  pinocchio::Data data(model);
  const Eigen::VectorXd g = pinocchio::computeGeneralizedGravity(model, data, r.q);
  BOOST_TEST_MESSAGE("|g| " << g.norm() << ", along the motion " << motion.dot(g));
  BOOST_CHECK_SMALL(motion.dot(g), 1e-7 * g.norm());
  BOOST_CHECK_GT(g.norm(), 1e-1); // the constraints carry load
  BOOST_CHECK(r.stability == pinsettle::Stability::Stable);
}
