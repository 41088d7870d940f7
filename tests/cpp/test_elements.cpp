//
// Boost.Test cases of the force elements (springs and loads), built against the installed
// package. The static force is checked against finite differences of the potential energy,
// which is computed here independently of the elements' fext path.
//

#define BOOST_TEST_MODULE pinsettle_elements
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <cmath>
#include <string>
#include <vector>

namespace
{
  const std::string robots_dir = PINSETTLE_ROBOTS_DIR;

  pinocchio::Model ur5()
  {
    return pinsettle::buildModelFromUrdf(robots_dir + "/ur_description/urdf/ur5_robot.urdf");
  }

  // A 1 kg bob 1 m below a hinge about y; q = 0 hangs down.
  pinocchio::Model pendulum()
  {
    pinocchio::Model model;
    const pinocchio::JointIndex j =
      model.addJoint(0, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "hinge");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(1., Eigen::Vector3d(0., 0., -1.), Eigen::Matrix3d::Identity() * 1e-3));
    model.addJointFrame(j);
    model.addBodyFrame("arm", j);
    return model;
  }

  Eigen::Vector3d worldPoint(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    pinocchio::FrameIndex frame,
    const Eigen::Vector3d & point)
  {
    pinocchio::forwardKinematics(model, data, q);
    return pinocchio::updateFramePlacement(model, data, frame).act(point);
  }
} // namespace

BOOST_AUTO_TEST_CASE(static_force_is_the_gradient_of_the_potential)
{
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model), ref(model);
  const pinocchio::FrameIndex tool = model.getFrameId("tool0");
  const pinocchio::FrameIndex forearm = model.getFrameId("forearm_link");
  const pinocchio::JointIndex elbow = model.getJointId("elbow_joint");
  const pinocchio::JointIndex wrist = model.getJointId("wrist_2_joint");
  const Eigen::Vector3d pa(0.01, 0.02, 0.03), anchor(0.4, 0.2, 0.6), pl(0., 0.1, 0.);
  const Eigen::Vector3d force(3., -2., -10.);

  pinsettle::ForceElements elements(model);
  elements.addPointSpring(tool, pa, 0, anchor, 200., 0.1);
  elements.addPointSpring(forearm, Eigen::Vector3d(0.1, 0., 0.), tool, pa, 50., 0.3);
  elements.addJointSpring(elbow, 20., 0.4);
  elements.addJointLoad(wrist, Eigen::VectorXd::Constant(1, 1.5));
  elements.addPointLoad(forearm, pl, force);
  BOOST_CHECK(elements.hasExternalForces());

  // V = gravity + springs - work of the constant loads.
  auto potential = [&](const Eigen::VectorXd & q) {
    double v = pinocchio::computePotentialEnergy(model, ref, q);
    const Eigen::Vector3d a = worldPoint(model, ref, q, tool, pa);
    const double l1 = (anchor - a).norm();
    const double l2 = (a - worldPoint(model, ref, q, forearm, Eigen::Vector3d(0.1, 0., 0.))).norm();
    v += 0.5 * 200. * (l1 - 0.1) * (l1 - 0.1) + 0.5 * 50. * (l2 - 0.3) * (l2 - 0.3);
    const double e = q[model.idx_qs[elbow]] - 0.4;
    v += 0.5 * 20. * e * e;
    v -= 1.5 * q[model.idx_qs[wrist]];
    v -= force.dot(worldPoint(model, ref, q, forearm, pl));
    return v;
  };

  std::srand(3);
  for (int trial = 0; trial < 10; ++trial)
  {
    const Eigen::VectorXd q = pinocchio::randomConfiguration(model);
    const Eigen::VectorXd ours = pinsettle::computeStaticForce(model, data, q, &elements);
    Eigen::VectorXd fd(model.nv);
    const double h = 1e-6;
    for (int k = 0; k < model.nv; ++k)
    {
      Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv);
      dq[k] = h;
      fd[k] = (potential(pinocchio::integrate(model, q, dq))
               - potential(pinocchio::integrate(model, q, -dq)))
              / (2. * h);
    }
    BOOST_CHECK_SMALL((ours - fd).lpNorm<Eigen::Infinity>(), 1e-5 * (1. + fd.norm()));
    BOOST_CHECK_CLOSE(
      pinsettle::computeStaticResidual(model, data, q, &elements), ours.lpNorm<Eigen::Infinity>(),
      1e-12);
  }
}

BOOST_AUTO_TEST_CASE(work_is_the_integral_of_the_efforts_along_the_path)
{
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model), ref(model);
  const pinocchio::FrameIndex tool = model.getFrameId("tool0");
  const pinocchio::FrameIndex forearm = model.getFrameId("forearm_link");
  pinsettle::ForceElements elements(model);
  elements.addPointSpring(
    tool, Eigen::Vector3d(0.01, 0.02, 0.03), 0, Eigen::Vector3d(0.4, 0.2, 0.6), 200., 0.1);
  elements.addJointSpring(model.getJointId("elbow_joint"), 20., 0.4);
  elements.addJointLoad(model.getJointId("wrist_2_joint"), Eigen::VectorXd::Constant(1, 1.5));
  elements.addPointLoad(forearm, Eigen::Vector3d(0., 0.1, 0.), Eigen::Vector3d(3., -2., -10.));

  std::srand(5);
  const Eigen::VectorXd q0 = pinocchio::randomConfiguration(model);
  const Eigen::VectorXd motion = 0.8 * Eigen::VectorXd::Random(model.nv);
  const Eigen::VectorXd q1 = pinocchio::integrate(model, q0, motion);
  // The work along the straight path, by the midpoint rule: the applied efforts are the static
  // force without the elements less the one with them; gravity's is the force without them.
  const int n = 4000;
  double elements_work = 0., gravity_work = 0.;
  for (int k = 0; k < n; ++k)
  {
    const Eigen::VectorXd q = pinocchio::integrate(model, q0, ((k + 0.5) / n) * motion);
    const Eigen::VectorXd bare = pinsettle::computeStaticForce(model, ref, q);
    const Eigen::VectorXd with = pinsettle::computeStaticForce(model, ref, q, &elements);
    elements_work += (bare - with).dot(motion) / n;
    gravity_work -= bare.dot(motion) / n;
  }
  BOOST_CHECK_CLOSE(elements.computeWork(model, data, q0, q1, motion), elements_work, 1e-5);
  const double gravity = pinsettle::computeGravityPotentialEnergy(model, data, q0)
                         - pinsettle::computeGravityPotentialEnergy(model, data, q1);
  BOOST_CHECK_CLOSE(gravity, gravity_work, 1e-5);
  BOOST_CHECK_CLOSE(
    pinsettle::computeGravityPotentialEnergy(model, data, q0),
    pinocchio::computePotentialEnergy(model, ref, q0), 1e-10);

  // A point torque's work depends on how the body turned on the way: not told.
  elements.addPointLoad(
    forearm, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d(0., 0., 1.));
  BOOST_CHECK(std::isnan(elements.computeWork(model, data, q0, q1, motion)));
  // A constant effort does tau . dq on every step: a wheel that turned twice under it has
  // received twice the turn's work, although it ends where it started.
  pinocchio::Model wheel;
  wheel.addJoint(0, pinocchio::JointModelRUBY(), pinocchio::SE3::Identity(), "wheel");
  pinocchio::Data wheel_data(wheel);
  const pinsettle::ConstantGeneralizedForce torque(Eigen::VectorXd::Constant(1, 0.5));
  const Eigen::VectorXd start = pinocchio::neutral(wheel);
  BOOST_CHECK_CLOSE(
    torque.computeWork(wheel, wheel_data, start, start, Eigen::VectorXd::Constant(1, 4. * M_PI)),
    2. * M_PI, 1e-12);
}

BOOST_AUTO_TEST_CASE(point_torque_acts_about_the_world_axis)
{
  const pinocchio::Model model = pendulum();
  pinocchio::Data data(model);
  pinsettle::ForceElements elements(model);
  // A torque about world y at the bob turns the hinge (axis y) whatever the point.
  elements.addPointLoad(
    model.getFrameId("arm"), Eigen::Vector3d(0., 0., -1.), Eigen::Vector3d::Zero(),
    Eigen::Vector3d(0., 2.5, 0.));
  for (double angle : {-1., 0., 0.3, 2.})
  {
    const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, angle);
    const double with = pinsettle::computeStaticForce(model, data, q, &elements)[0];
    const double without = pinsettle::computeStaticForce(model, data, q)[0];
    BOOST_CHECK_CLOSE(without - with, 2.5, 1e-10);
  }
}

BOOST_AUTO_TEST_CASE(spring_damping_dissipates_c_times_rate_squared)
{
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model), ref(model);
  const pinocchio::FrameIndex tool = model.getFrameId("tool0");
  const Eigen::Vector3d anchor(0.3, -0.2, 0.5);
  const double c = 7.;
  pinsettle::ForceElements damped(model), plain(model);
  damped.addPointSpring(tool, Eigen::Vector3d::Zero(), 0, anchor, 100., 0.05, c);
  plain.addPointSpring(tool, Eigen::Vector3d::Zero(), 0, anchor, 100., 0.05, 0.);
  damped.addJointSpring(1, 10., 0., 3.);
  plain.addJointSpring(1, 10., 0., 0.);

  std::srand(5);
  const Eigen::VectorXd q = pinocchio::randomConfiguration(model);
  const Eigen::VectorXd v = Eigen::VectorXd::Random(model.nv);
  auto generalized = [&](const pinsettle::ForceElements & elements) {
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    pinsettle::ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
    elements.computeForces(model, data, q, v, tau, fext);
    // Spatial forces to generalized forces: rnea(q, 0, 0) - rnea(q, 0, 0, fext) = J^T fext.
    // (rnea returns a reference to ref.tau: copy each result before the next call.)
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    const Eigen::VectorXd gravity = pinocchio::rnea(model, ref, q, zero, zero);
    const Eigen::VectorXd with_fext = pinocchio::rnea(model, ref, q, zero, zero, fext);
    return Eigen::VectorXd(tau + gravity - with_fext);
  };
  const double power = (generalized(damped) - generalized(plain)).dot(v);
  // Rate of the spring length along v, by finite differences.
  const double h = 1e-7;
  auto length = [&](double t) {
    return (anchor
            - worldPoint(
              model, ref, pinocchio::integrate(model, q, t * v), tool, Eigen::Vector3d::Zero()))
      .norm();
  };
  const double rate = (length(h) - length(-h)) / (2. * h);
  const double joint_rate = v[model.idx_vs[1]];
  BOOST_CHECK_CLOSE(power, -c * rate * rate - 3. * joint_rate * joint_rate, 1e-5);
}

BOOST_AUTO_TEST_CASE(continuous_joint_spring_wraps_the_angle)
{
  pinocchio::Model model;
  const pinocchio::JointIndex j =
    model.addJoint(0, pinocchio::JointModelRUBY(), pinocchio::SE3::Identity(), "wheel");
  model.appendBodyToJoint(j, pinocchio::Inertia::Identity());
  model.gravity.setZero();
  pinocchio::Data data(model);
  pinsettle::ForceElements elements(model);
  elements.addJointSpring(j, 2., 3.); // rest near pi
  // At angle -3 the shortest way to the rest angle 3 is through pi: stretch 2 pi - 6.
  const Eigen::Vector2d q(std::cos(-3.), std::sin(-3.));
  const double force = pinsettle::computeStaticForce(model, data, q, &elements)[0];
  BOOST_CHECK_CLOSE(force, 2. * (-6. + 2. * M_PI), 1e-9);
}

BOOST_AUTO_TEST_CASE(empty_elements_step_exactly_like_the_bare_core)
{
  const pinocchio::Model model = ur5();
  pinsettle::ForceElements none(model);
  BOOST_CHECK(none.empty());
  pinsettle::Solver a(model), b(model);
  const Eigen::VectorXd q0 = pinocchio::neutral(model);
  const pinsettle::Result bare = a.solve(q0);
  const pinsettle::Result with = b.solve(q0, pinsettle::Settings(), &none);
  BOOST_CHECK_EQUAL(bare.info.steps, with.info.steps);
  BOOST_CHECK(bare.q == with.q);
}

BOOST_AUTO_TEST_CASE(bistable_pendulum_settles_on_either_side)
{
  // A compressed spring from the bob to a point 1 m below it pushes the bob off the bottom.
  const pinocchio::Model model = pendulum();
  pinsettle::ForceElements elements(model);
  elements.addPointSpring(
    model.getFrameId("arm"), Eigen::Vector3d(0., 0., -1.), 0, Eigen::Vector3d(0., 0., -2.), 40.,
    1.5);
  pinsettle::Solver solver(model);
  pinsettle::Settings settings;
  settings.max_e = 1e-20;
  const pinsettle::Result right =
    solver.solve(Eigen::VectorXd::Constant(1, 0.2), settings, &elements);
  const pinsettle::Result left =
    solver.solve(Eigen::VectorXd::Constant(1, -0.2), settings, &elements);
  BOOST_CHECK(right.status == pinsettle::Status::Converged);
  BOOST_CHECK(left.status == pinsettle::Status::Converged);
  BOOST_CHECK_GT(right.q[0], 0.5);
  BOOST_CHECK_CLOSE(right.q[0], -left.q[0], 1e-6);
  BOOST_CHECK_SMALL(right.residual, 1e-6);
  // Independent: dV/dq = m g l sin q + k (d - L0) dd/dq with d^2 = 5 - 4 cos q.
  const double t = right.q[0], d = std::sqrt(5. - 4. * std::cos(t));
  BOOST_CHECK_SMALL(9.81 * std::sin(t) + 40. * (d - 1.5) * 2. * std::sin(t) / d, 1e-6);
}

BOOST_AUTO_TEST_CASE(bad_elements_are_rejected)
{
  const pinocchio::Model model = ur5();
  pinsettle::ForceElements elements(model);
  auto rejects = [](const std::function<void()> & f, const std::string & fragment) {
    try
    {
      f();
      BOOST_ERROR("accepted; expected a message with '" + fragment + "'");
    }
    catch (const std::invalid_argument & e)
    {
      BOOST_CHECK_MESSAGE(
        std::string(e.what()).find(fragment) != std::string::npos,
        "message '" << e.what() << "' lacks '" << fragment << "'");
    }
  };
  const pinocchio::FrameIndex tool = model.getFrameId("tool0");
  rejects([&] { elements.addJointSpring(1, -1.); }, "stiffness");
  rejects([&] { elements.addJointSpring(1, 1., 0., -2.); }, "damping");
  rejects([&] { elements.addJointSpring(99, 1.); }, "joint index 99");
  rejects(
    [&] { elements.addPointSpring(tool, Eigen::Vector3d::Zero(), 0, {0., 0., 0.}, 1., -1.); },
    "rest_length");
  rejects(
    [&] { elements.addPointSpring(9999, Eigen::Vector3d::Zero(), 0, {0., 0., 0.}, 1.); },
    "frame index 9999");
  rejects(
    [&] { elements.addPointSpring(tool, Eigen::Vector3d::Zero(), tool, {0., 0., 1.}, 1.); },
    "same rigid body");
  rejects([&] { elements.addJointLoad(1, Eigen::VectorXd::Zero(2)); }, "degrees of freedom");
  rejects(
    [&] { elements.addPointLoad(tool, Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(NAN)); },
    "force");

  pinocchio::Model ball;
  ball.addJoint(0, pinocchio::JointModelSpherical(), pinocchio::SE3::Identity(), "ball");
  pinsettle::ForceElements on_ball(ball);
  rejects([&] { on_ball.addJointSpring(1, 1.); }, "1-DoF");
  BOOST_CHECK(elements.empty());
}

namespace
{
  // Central differences of the static force (computeStaticForce: aba's fext path), step 1e-6
  // along each tangent direction; forces may be nullptr (gravity alone).
  Eigen::MatrixXd differencedStiffness(
    const pinocchio::Model & model, const Eigen::VectorXd & q, const pinsettle::ForceModel * forces)
  {
    pinocchio::Data data(model);
    Eigen::MatrixXd fd(model.nv, model.nv);
    for (int k = 0; k < model.nv; ++k)
    {
      Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv);
      dq[k] = 1e-6;
      fd.col(k) =
        (pinsettle::computeStaticForce(model, data, pinocchio::integrate(model, q, dq), forces)
         - pinsettle::computeStaticForce(model, data, pinocchio::integrate(model, q, -dq), forces))
        / 2e-6;
    }
    return fd;
  }

  void addBody(pinocchio::Model & model, pinocchio::JointIndex joint, double mass)
  {
    model.appendBodyToJoint(
      joint, pinocchio::Inertia(
               mass, Eigen::Vector3d(0.1, -0.05, -0.3),
               Eigen::Vector3d(0.02, 0.03, 0.01).asDiagonal().toDenseMatrix()));
    model.addJointFrame(joint);
    model.addBodyFrame("body_" + model.names[joint], joint);
  }
} // namespace

BOOST_AUTO_TEST_CASE(stiffness_matrix_matches_finite_differences)
{
  // Gravity's part is analytic, the elements' part in closed form: compare the whole with
  // central differences of computeStaticForce taken here.
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model);
  pinsettle::ForceElements elements(model);
  elements.addPointSpring(
    model.getFrameId("tool0"), Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0.4, 0.2, 0.6), 200.);
  elements.addJointSpring(2, 15., 0.3);
  // A load fixed in the world on a point of a body, and an effort on a joint: the external
  // forces' mapping to the joints moves with q too.
  elements.addPointLoad(
    model.getFrameId("tool0"), Eigen::Vector3d(0.05, 0., 0.1), Eigen::Vector3d(3., -2., 5.));
  elements.addJointLoad(4, Eigen::VectorXd::Constant(1, 1.5));
  std::srand(11);
  for (const pinsettle::ForceModel * forces :
       {static_cast<const pinsettle::ForceModel *>(nullptr),
        static_cast<const pinsettle::ForceModel *>(&elements)})
  {
    const Eigen::VectorXd q = pinocchio::randomConfiguration(model);
    const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, data, q, forces);
    const Eigen::MatrixXd fd = differencedStiffness(model, q, forces);
    BOOST_CHECK_SMALL((K - fd).lpNorm<Eigen::Infinity>(), 1e-5 * (1. + fd.norm()));
  }
}

BOOST_AUTO_TEST_CASE(joint_springs_and_loads_give_their_stiffness_in_closed_form)
{
  // Without point springs or loads K = dg/dq + diag(k): no differences, and the verdict's
  // tolerance is the analytic 1e-9. Checked against central differences of the static force,
  // on revolute joints and on a continuous one (its spring acts on the angle atan2(s, c)).
  const pinocchio::Model arm = ur5();
  pinsettle::ForceElements elements(arm);
  elements.addJointSpring(2, 15., 0.3);
  elements.addJointSpring(5, 400., -0.2);
  elements.addJointLoad(4, Eigen::VectorXd::Constant(1, 1.5));
  BOOST_CHECK(elements.hasClosedFormStiffness());
  BOOST_CHECK(!pinsettle::stiffnessByFiniteDifferences(arm, &elements));
  std::srand(3);
  pinocchio::Data data(arm);
  const Eigen::VectorXd q = pinocchio::randomConfiguration(arm);
  const Eigen::MatrixXd fd = differencedStiffness(arm, q, &elements);
  BOOST_CHECK_SMALL(
    (pinsettle::computeStiffnessMatrix(arm, data, q, &elements) - fd).lpNorm<Eigen::Infinity>(),
    1e-6 * (1. + fd.norm()));

  pinocchio::Model wheel;
  const pinocchio::JointIndex j =
    wheel.addJoint(0, pinocchio::JointModelRUBY(), pinocchio::SE3::Identity(), "wheel");
  wheel.appendBodyToJoint(
    j, pinocchio::Inertia(2., Eigen::Vector3d(0., 0., -0.3), Eigen::Matrix3d::Identity() * 1e-2));
  pinsettle::ForceElements coil(wheel);
  coil.addJointSpring(j, 9., 0.4);
  const Eigen::Vector2d at(std::cos(2.), std::sin(2.)); // 2 rad: 1.6 rad of stretch
  pinocchio::Data wheel_data(wheel);
  const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(wheel, wheel_data, at, &coil);
  BOOST_CHECK_SMALL((K - differencedStiffness(wheel, at, &coil)).lpNorm<Eigen::Infinity>(), 1e-6);

  // A point load on the arm: closed form too (the next case checks it on every joint kind).
  pinsettle::ForceElements loaded(arm);
  loaded.addPointLoad(
    arm.getFrameId("tool0"), Eigen::Vector3d::Zero(), Eigen::Vector3d(0., 0., -5.));
  BOOST_CHECK(loaded.hasClosedFormStiffness());
  BOOST_CHECK(!pinsettle::stiffnessByFiniteDifferences(arm, &loaded));
}

BOOST_AUTO_TEST_CASE(point_springs_and_loads_give_their_stiffness_in_closed_form)
{
  // A tree (in depth-first order, as Pinocchio's algorithms need) with every joint kind the
  // closed form covers, several degrees of freedom per joint included (the columns of one joint
  // turn each other): springs between moving bodies with and without a rest length, one to the
  // world, loads with and without a torque. K (gravity analytic, the elements in closed form)
  // against central differences of the static force.
  pinocchio::Model model;
  const auto placement = [](double x, double y, double z) {
    return pinocchio::SE3(
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1., 2., 3.).normalized()).toRotationMatrix(),
      Eigen::Vector3d(x, y, z));
  };
  const pinocchio::JointIndex base =
    model.addJoint(0, pinocchio::JointModelFreeFlyer(), placement(0., 0., 1.), "base");
  const pinocchio::JointIndex ball =
    model.addJoint(base, pinocchio::JointModelSpherical(), placement(0.2, 0., 0.), "ball");
  const pinocchio::JointIndex planar =
    model.addJoint(ball, pinocchio::JointModelPlanar(), placement(0., 0.3, -0.2), "planar");
  const pinocchio::JointIndex cross =
    model.addJoint(planar, pinocchio::JointModelTranslation(), placement(0., 0., -0.1), "cross");
  const pinocchio::JointIndex slider =
    model.addJoint(base, pinocchio::JointModelPY(), placement(-0.2, 0.1, 0.), "slider");
  const pinocchio::JointIndex screw = model.addJoint(
    slider, pinocchio::JointModelHelicalUnaligned(Eigen::Vector3d(1., 1., 0.).normalized(), 0.05),
    placement(0., 0., -0.4), "screw");
  const pinocchio::JointIndex wheel =
    model.addJoint(screw, pinocchio::JointModelRUBX(), placement(0.1, 0., 0.), "wheel");
  const pinocchio::JointIndex hinge = model.addJoint(
    wheel, pinocchio::JointModelRevoluteUnaligned(Eigen::Vector3d(0., 1., 1.).normalized()),
    placement(0., -0.2, 0.), "hinge");
  for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    addBody(model, j, 0.5 + 0.25 * static_cast<double>(j));
  const auto frame = [&](pinocchio::JointIndex j) {
    return model.getFrameId("body_" + model.names[j]);
  };

  pinsettle::ForceElements elements(model);
  elements.addPointSpring(
    frame(cross), Eigen::Vector3d(0.1, 0., 0.05), frame(hinge), Eigen::Vector3d(0., 0.2, 0.), 80.,
    0.3);
  elements.addPointSpring(
    frame(planar), Eigen::Vector3d(0.05, 0.1, 0.), frame(wheel), Eigen::Vector3d::Zero(), 30.);
  elements.addPointSpring(
    0, Eigen::Vector3d(0.5, -0.4, 2.), frame(ball), Eigen::Vector3d(0., 0.1, 0.2), 120., 0.4);
  elements.addPointLoad(
    frame(hinge), Eigen::Vector3d(0.02, 0., 0.1), Eigen::Vector3d(3., -2., 5.),
    Eigen::Vector3d(0.4, 0.1, -0.3));
  elements.addPointLoad(frame(base), Eigen::Vector3d(0.1, 0.1, 0.), Eigen::Vector3d(0., 7., -1.));
  elements.addJointSpring(slider, 40., 0.1);
  BOOST_CHECK(elements.hasClosedFormStiffness());
  BOOST_CHECK(!pinsettle::stiffnessByFiniteDifferences(model, &elements));

  pinocchio::Data data(model);
  std::srand(5);
  for (int trial = 0; trial < 3; ++trial)
  {
    // integrate normalises a quaternion to first order only: a step this long leaves it 1e-3
    // off the unit sphere, where the differences and the derivatives part.
    Eigen::VectorXd q =
      pinocchio::integrate(model, pinocchio::neutral(model), Eigen::VectorXd::Random(model.nv));
    pinocchio::normalize(model, q);
    const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, data, q, &elements);
    const Eigen::MatrixXd fd = differencedStiffness(model, q, &elements);
    BOOST_TEST_CONTEXT("trial " << trial)
    BOOST_CHECK_SMALL((K - fd).lpNorm<Eigen::Infinity>(), 1e-6 * (1. + fd.norm()));
    // The elements' share is not small next to gravity's: the check would see it missing.
    const Eigen::MatrixXd gravity_only = pinsettle::computeStiffnessMatrix(model, data, q);
    BOOST_CHECK_GT((K - gravity_only).lpNorm<Eigen::Infinity>(), 10.);
  }
}

BOOST_AUTO_TEST_CASE(joints_whose_subspace_turns_are_differenced)
{
  // A universal joint's, a ZYX spherical's and an ellipsoid's motion subspaces turn with their
  // own angles: Pinocchio's gravity derivatives miss that turn and a point load has no closed
  // form. K, with gravity alone and with a load, against central differences.
  const std::vector<pinocchio::JointModel> joints = {
    pinocchio::JointModelUniversal(Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()),
    pinocchio::JointModelSphericalZYX(), pinocchio::JointModelEllipsoid(0.1, 0.2, 0.3)};
  for (const pinocchio::JointModel & kind : joints)
  {
    BOOST_TEST_CONTEXT(kind.shortname())
    {
      pinocchio::Model model;
      const pinocchio::JointIndex joint =
        model.addJoint(0, kind, pinocchio::SE3::Identity(), "gimbal");
      addBody(model, joint, 2.);
      pinsettle::ForceElements elements(model);
      elements.addPointLoad(
        model.getFrameId("body_gimbal"), Eigen::Vector3d(0., 0., -0.5),
        Eigen::Vector3d(1., 2., -3.));
      BOOST_CHECK(!elements.hasClosedFormStiffness());
      BOOST_CHECK(pinsettle::stiffnessByFiniteDifferences(model, nullptr));
      pinocchio::Data data(model);
      const Eigen::VectorXd q = Eigen::VectorXd::LinSpaced(model.nq, 0.4, -0.7);
      for (const pinsettle::ForceModel * forces :
           {static_cast<const pinsettle::ForceModel *>(nullptr),
            static_cast<const pinsettle::ForceModel *>(&elements)})
      {
        const Eigen::MatrixXd fd = differencedStiffness(model, q, forces);
        BOOST_CHECK_SMALL(
          (pinsettle::computeStiffnessMatrix(model, data, q, forces) - fd)
            .lpNorm<Eigen::Infinity>(),
          1e-6 * (1. + fd.norm()));
      }
    }
  }
}

BOOST_AUTO_TEST_CASE(damping_matrix_matches_finite_differences_of_rnea)
{
  // D = -d applied / d v, the applied efforts' joint torques recomputed here with Pinocchio's
  // RNEA (gravity minus RNEA with the external forces) rather than the solver's own mapping.
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model), reference(model);
  pinsettle::ForceElements elements(model);
  elements.addPointSpring(
    model.getFrameId("tool0"), Eigen::Vector3d(0.02, 0., 0.05), 0, Eigen::Vector3d(0.4, 0.2, 0.6),
    200., 0.1, 7.);
  elements.addJointSpring(3, 15., 0.3, 2.);
  std::srand(5);
  const Eigen::VectorXd q = pinocchio::randomConfiguration(model);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
  const auto applied = [&](const Eigen::VectorXd & v) {
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    pinsettle::ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
    elements.computeForces(model, reference, q, v, tau, fext);
    return Eigen::VectorXd(
      tau + pinocchio::computeGeneralizedGravity(model, reference, q)
      - pinocchio::rnea(model, reference, q, zero, zero, fext));
  };
  Eigen::MatrixXd fd(model.nv, model.nv);
  for (int k = 0; k < model.nv; ++k)
  {
    Eigen::VectorXd v = zero;
    v[k] = 1e-6;
    fd.col(k) = -(applied(v) - applied(-v)) / 2e-6;
  }
  const Eigen::MatrixXd D = pinsettle::computeDampingMatrix(model, data, q, &elements);
  BOOST_CHECK_GT(fd.norm(), 1.);
  BOOST_CHECK_SMALL((D - fd).lpNorm<Eigen::Infinity>(), 1e-6 * (1. + fd.norm()));
}

BOOST_AUTO_TEST_CASE(stability_verdicts_of_a_pendulum)
{
  // K = m g l cos q: stable hanging down, unstable upright, neutral without gravity.
  pinocchio::Model model = pendulum();
  pinocchio::Data data(model);
  const pinsettle::StabilityReport down =
    pinsettle::assessStability(model, data, Eigen::VectorXd::Constant(1, 0.));
  BOOST_CHECK(down.verdict == pinsettle::Stability::Stable);
  BOOST_CHECK_CLOSE(down.min_eigenvalue, 9.81, 1e-9);
  const pinsettle::StabilityReport up =
    pinsettle::assessStability(model, data, Eigen::VectorXd::Constant(1, M_PI));
  BOOST_CHECK(up.verdict == pinsettle::Stability::Unstable);
  BOOST_CHECK_CLOSE(up.min_eigenvalue, -9.81, 1e-9);
  model.gravity.setZero();
  pinocchio::Data free_data(model);
  const pinsettle::StabilityReport free =
    pinsettle::assessStability(model, free_data, Eigen::VectorXd::Constant(1, 1.));
  BOOST_CHECK(free.verdict == pinsettle::Stability::Neutral);
  BOOST_CHECK_EQUAL(free.neutral_directions, 1);
}

BOOST_AUTO_TEST_CASE(released_on_a_saddle_the_ur5_is_pushed_to_a_stable_rest)
{
  // The UR5 at [0, pi/2, 0, pi/2, 0, 0] is a saddle (an optimiser's answer from the zero
  // pose): released there at rest it must not be reported converged there.
  const pinocchio::Model model = ur5();
  pinocchio::Data data(model);
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(6);
  q0[1] = q0[3] = M_PI / 2.;
  BOOST_CHECK(
    pinsettle::assessStability(model, data, q0).verdict == pinsettle::Stability::Unstable);
  pinsettle::Solver solver(model);
  const pinsettle::Result result = solver.solve(q0);
  BOOST_CHECK(result.status == pinsettle::Status::Converged);
  BOOST_CHECK_GE(result.info.pushes, 1);
  BOOST_CHECK(result.stability != pinsettle::Stability::Unstable);
  BOOST_CHECK(
    pinsettle::assessStability(model, data, result.q).verdict != pinsettle::Stability::Unstable);
  BOOST_CHECK_SMALL(result.residual, 1e-5);
}
