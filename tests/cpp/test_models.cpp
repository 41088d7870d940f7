//
// Boost.Test cases of pinsettle::checkSupportedModel: a model the algorithms pinsettle runs do
// not support is refused with a message naming the joint, never run into a crash.
//

#define BOOST_TEST_MODULE pinsettle_models
#include <boost/test/unit_test.hpp>

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/model.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody/sample-models.hpp>

#include <stdexcept>
#include <string>

namespace
{

  // Two links hanging from hinges about y, 0.5 m each, 1 kg at their middles.
  pinocchio::Model twoLinks()
  {
    pinocchio::Model model;
    const pinocchio::Inertia link(
      1., Eigen::Vector3d(0., 0., -0.25), Eigen::Matrix3d::Identity() * 1e-2);
    const pinocchio::JointIndex j1 =
      model.addJoint(0, pinocchio::JointModelRY(), pinocchio::SE3::Identity(), "joint1");
    model.appendBodyToJoint(j1, link);
    const pinocchio::JointIndex j2 = model.addJoint(
      j1, pinocchio::JointModelRY(),
      pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., -0.5)), "joint2");
    model.appendBodyToJoint(j2, link);
    return model;
  }

  // The same, joint2 following joint1 as pinocchio.buildModelFromUrdf(path, mimic=True) makes of
  // <mimic joint="joint1" multiplier="-1.5" offset="0.25"/>: q[joint2] = -1.5 q[joint1] + 0.25.
  pinocchio::Model twoLinksWithMimic()
  {
    pinocchio::Model model;
    pinocchio::transformJointIntoMimic(twoLinks(), 1, 2, -1.5, 0.25, model);
    return model;
  }

  std::string refusal(const pinocchio::Model & model)
  {
    try
    {
      pinsettle::checkSupportedModel(model);
    }
    catch (const std::invalid_argument & e)
    {
      return e.what();
    }
    return "";
  }

  bool contains(const std::string & text, const std::string & part)
  {
    return text.find(part) != std::string::npos;
  }

} // namespace

BOOST_AUTO_TEST_CASE(mimic_joint_is_refused_with_its_name_and_why)
{
  const pinocchio::Model model = twoLinksWithMimic();
  // The model really holds a mimic joint, as Pinocchio's URDF parser makes it.
  BOOST_REQUIRE_EQUAL(model.mimicking_joints.size(), 1u);
  BOOST_REQUIRE_EQUAL(model.joints[2].shortname(), "JointModelMimic");
  BOOST_REQUIRE_EQUAL(model.nv, 1);

  const std::string message = refusal(model);
  BOOST_TEST_MESSAGE(message);
  BOOST_CHECK(contains(message, "'joint2'"));
  BOOST_CHECK(contains(message, "mimic joint of 'joint1'"));
  BOOST_CHECK(contains(message, "q_follower = multiplier * q_leader + offset"));
  BOOST_CHECK(contains(message, "q[joint2] = -1.5 * q[joint1] + 0.25"));
  BOOST_CHECK(contains(message, "releaseMimicJoints"));
  BOOST_CHECK(contains(message, "mimic=False"));

  // Pinocchio's own sample manipulator with its mimic joint.
  pinocchio::Model manipulator;
  pinocchio::buildModels::manipulator(manipulator, true);
  BOOST_REQUIRE(!manipulator.mimicking_joints.empty());
  const std::string name = manipulator.names[manipulator.mimicking_joints.front()];
  BOOST_CHECK(contains(refusal(manipulator), "'" + name + "'"));
}

BOOST_AUTO_TEST_CASE(supported_models_pass)
{
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(twoLinks()));

  pinocchio::Model manipulator;
  pinocchio::buildModels::manipulator(manipulator);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(manipulator));

  pinocchio::Model humanoid;
  pinocchio::buildModels::humanoidRandom(humanoid, true);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(humanoid));

  // A composite joint of supported parts, and the joint types beside it.
  pinocchio::Model model;
  pinocchio::JointModelComposite composite;
  composite.addJoint(pinocchio::JointModelRX());
  composite.addJoint(pinocchio::JointModelRY());
  const pinocchio::JointIndex j =
    model.addJoint(0, composite, pinocchio::SE3::Identity(), "composite");
  model.appendBodyToJoint(j, pinocchio::Inertia::Random());
  model.addJoint(j, pinocchio::JointModelPlanar(), pinocchio::SE3::Random(), "planar");
  // Axes given: the default constructors of these two leave them uninitialized.
  model.addJoint(
    2, pinocchio::JointModelUniversal(Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()),
    pinocchio::SE3::Random(), "universal");
  model.addJoint(
    3, pinocchio::JointModelHelicalUnaligned(Eigen::Vector3d(0., 0.6, 0.8), 0.05),
    pinocchio::SE3::Random(), "helical");
  model.addJoint(4, pinocchio::JointModelEllipsoid(), pinocchio::SE3::Random(), "ellipsoid");
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(model));
}

BOOST_AUTO_TEST_CASE(tables_changed_by_hand_are_refused)
{
  // Pinocchio's algorithms index these tables without checking them.
  pinocchio::Model parents = twoLinks();
  parents.parents[2] = 2;
  const std::string message = refusal(parents);
  BOOST_CHECK(contains(message, "'joint2'"));
  BOOST_CHECK(contains(message, "parent"));

  pinocchio::Model inertias = twoLinks();
  inertias.inertias.pop_back();
  BOOST_CHECK(contains(refusal(inertias), "inertias"));

  pinocchio::Model names = twoLinks();
  names.names.push_back("extra");
  BOOST_CHECK(contains(refusal(names), "names"));
}

BOOST_AUTO_TEST_CASE(joints_out_of_depth_first_order_are_refused)
{
  // a, then b on the root, then c on a: a's subtree {a, c} is not a run of indices, and
  // crba's mass matrix misses the coupling of a and c (aba and rnea stay right).
  pinocchio::Model model;
  const pinocchio::Inertia body(
    1., Eigen::Vector3d(0.1, 0.2, -0.5), Eigen::Matrix3d::Identity() * 0.1);
  const pinocchio::JointIndex a =
    model.addJoint(0, pinocchio::JointModelRX(), pinocchio::SE3::Identity(), "a");
  model.appendBodyToJoint(a, body);
  const pinocchio::JointIndex b =
    model.addJoint(0, pinocchio::JointModelPX(), pinocchio::SE3::Identity(), "b");
  model.appendBodyToJoint(b, body);
  const pinocchio::JointIndex c =
    model.addJoint(a, pinocchio::JointModelPY(), pinocchio::SE3::Identity(), "c");
  model.appendBodyToJoint(c, body);
  const std::string message = refusal(model);
  BOOST_TEST_MESSAGE(message);
  BOOST_CHECK(contains(message, "'c'"));
  BOOST_CHECK(contains(message, "depth-first"));

  // The same mechanism in depth-first order passes.
  pinocchio::Model ordered;
  const pinocchio::JointIndex a2 =
    ordered.addJoint(0, pinocchio::JointModelRX(), pinocchio::SE3::Identity(), "a");
  ordered.appendBodyToJoint(a2, body);
  const pinocchio::JointIndex c2 =
    ordered.addJoint(a2, pinocchio::JointModelPY(), pinocchio::SE3::Identity(), "c");
  ordered.appendBodyToJoint(c2, body);
  const pinocchio::JointIndex b2 =
    ordered.addJoint(0, pinocchio::JointModelPX(), pinocchio::SE3::Identity(), "b");
  ordered.appendBodyToJoint(b2, body);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(ordered));
}

BOOST_AUTO_TEST_CASE(stiffness_of_a_composite_joint_is_the_derivative_of_gravity)
{
  // Pinocchio 4.1's computeGeneralizedGravityDerivatives drops the coupling between the parts
  // of a composite joint (RX then RY gets a triangular block); the stiffness pinsettle uses
  // must be the true derivative of gravity, checked here by central differences of
  // pinocchio::computeGeneralizedGravity, and symmetric (gravity has a potential).
  for (const bool prismatic : {false, true})
  {
    pinocchio::Model model;
    pinocchio::JointModelComposite composite;
    if (prismatic)
      composite.addJoint(pinocchio::JointModelPX());
    composite.addJoint(pinocchio::JointModelRX());
    composite.addJoint(pinocchio::JointModelRY());
    const pinocchio::JointIndex j =
      model.addJoint(0, composite, pinocchio::SE3::Identity(), "composite");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(
           1., Eigen::Vector3d(0.1, 0.2, -0.5), Eigen::Vector3d(0.1, 0.2, 0.3).asDiagonal()));
    pinocchio::Data data(model);
    Eigen::VectorXd q(model.nq);
    q.setLinSpaced(0.3, -0.4);

    const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, data, q);
    Eigen::MatrixXd reference(model.nv, model.nv);
    const double h = 1e-6;
    for (int k = 0; k < model.nv; ++k)
    {
      Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv);
      dq[k] = h;
      const Eigen::VectorXd plus = pinocchio::integrate(model, q, dq);
      const Eigen::VectorXd minus = pinocchio::integrate(model, q, -dq);
      // computeGeneralizedGravity returns data.g: copy it before the second call.
      const Eigen::VectorXd g_plus = pinocchio::computeGeneralizedGravity(model, data, plus);
      const Eigen::VectorXd g_minus = pinocchio::computeGeneralizedGravity(model, data, minus);
      reference.col(k) = (g_plus - g_minus) / (2. * h);
    }
    BOOST_TEST_MESSAGE("K =\n" << K << "\nreference =\n" << reference);
    BOOST_CHECK_LT((K - reference).cwiseAbs().maxCoeff(), 1e-6);
    BOOST_CHECK_LT((K - K.transpose()).cwiseAbs().maxCoeff(), 1e-6);
    BOOST_CHECK(pinsettle::stiffnessByFiniteDifferences(model, nullptr));
    // Why: Pinocchio's own derivative is not that (the day this fails, Pinocchio is fixed and
    // computeStiffnessMatrix can go back to it for composite joints).
    Eigen::MatrixXd analytic = Eigen::MatrixXd::Zero(model.nv, model.nv);
    pinocchio::computeGeneralizedGravityDerivatives(model, data, q, analytic);
    BOOST_CHECK_GT((analytic - reference).cwiseAbs().maxCoeff(), 0.1);
  }
  pinocchio::Model manipulator;
  pinocchio::buildModels::manipulator(manipulator);
  BOOST_CHECK(!pinsettle::stiffnessByFiniteDifferences(manipulator, nullptr));
}

BOOST_AUTO_TEST_CASE(a_data_that_would_not_fit_in_memory_is_refused_before_it_is_made)
{
  // A chain of n hinges (Model only: a Data of the refused one would hold 32 nv^3 bytes).
  auto chain = [](int n) {
    pinocchio::Model model;
    pinocchio::JointIndex parent = 0;
    for (int k = 0; k < n; ++k)
    {
      parent = model.addJoint(
        parent, pinocchio::JointModelRY(),
        pinocchio::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0., 0., k ? -0.1 : 0.)),
        "joint" + std::to_string(k + 1));
      model.appendBodyToJoint(
        parent, pinocchio::Inertia(
                  0.1, Eigen::Vector3d(0., 0., -0.05), Eigen::Matrix3d::Identity() * 1e-4));
    }
    return model;
  };
  // The model itself is supported whatever its size; what a Data of it takes is checked where
  // one is made, against the memory the machine has.
  const pinocchio::Model large = chain(1000);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(large));
  const double bytes = static_cast<double>(pinsettle::computeDataMemory(large));
  BOOST_CHECK_GE(bytes, 32e9);        // the four nv^3 tensors
  BOOST_CHECK_LE(bytes, 1.01 * 32e9); // and the rest, a small part at this size
  // More Data than the machine has memory for (whatever that is): refused, with the figures.
  const std::size_t available = pinsettle::availableMemory();
  BOOST_REQUIRE_GT(available, 0u);
  const int count = static_cast<int>(static_cast<double>(available) / bytes) + 1;
  BOOST_CHECK(!pinsettle::fitsInMemory(large, count));
  BOOST_CHECK(pinsettle::fitsInMemory(chain(322), 1));
  std::string message;
  try
  {
    pinsettle::checkDataMemory(large, count, "the test");
  }
  catch (const pinsettle::MemoryLimitError & e)
  {
    message = e.what();
  }
  BOOST_TEST_MESSAGE(message);
  BOOST_CHECK(contains(message, "model.nv = 1000"));
  BOOST_CHECK(contains(message, count == 1 ? "a pinocchio.Data of 32.2 GB" : "32.2 GB each"));
  BOOST_CHECK(contains(message, "the test needs"));
  BOOST_CHECK(contains(message, "available"));
  // A model whose Data fits is made, as before: the largest the old fixed limit took and one
  // past it.
  BOOST_CHECK_NO_THROW(pinsettle::checkDataMemory(chain(322), 1, "the test"));
  const pinocchio::Data data = pinsettle::makeData(chain(330), "the test");
  BOOST_CHECK_EQUAL(data.d2tau_dqdq.dimension(0), 330);
}

BOOST_AUTO_TEST_CASE(joints_whose_axis_is_not_a_unit_vector_are_refused)
{
  // What Pinocchio's URDF parser makes of <axis xyz="0 0 0">: an unaligned joint with a zero
  // axis (it normalizes any other), whose motion would be no rotation at all. The axes are set
  // after construction: the constructors assert unit axes in a debug build.
  auto oneJoint = [](const pinocchio::JointModel & joint) {
    pinocchio::Model model;
    const pinocchio::JointIndex j = model.addJoint(0, joint, pinocchio::SE3::Identity(), "axis");
    model.appendBodyToJoint(
      j, pinocchio::Inertia(1., Eigen::Vector3d(0., 0., -0.5), Eigen::Matrix3d::Identity() * 1e-2));
    return model;
  };
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  const Eigen::Vector3d unit = Eigen::Vector3d(1., 2., 2.) / 3.;
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY();

  pinocchio::JointModelRevoluteUnaligned revolute(unit);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(oneJoint(revolute)));
  revolute.axis = zero;
  const std::string message = refusal(oneJoint(revolute));
  BOOST_TEST_MESSAGE(message);
  BOOST_CHECK(contains(message, "'axis'") && contains(message, "(0, 0, 0), not a unit vector"));

  pinocchio::JointModelPrismaticUnaligned prismatic(unit);
  prismatic.axis = 2. * unit;
  BOOST_CHECK(contains(refusal(oneJoint(prismatic)), "not a unit vector"));
  pinocchio::JointModelRevoluteUnboundedUnaligned unbounded(unit);
  unbounded.axis = zero;
  BOOST_CHECK(contains(refusal(oneJoint(unbounded)), "not a unit vector"));
  pinocchio::JointModelHelicalUnaligned helical(unit, 0.1);
  helical.axis = zero;
  BOOST_CHECK(contains(refusal(oneJoint(helical)), "not a unit vector"));

  pinocchio::JointModelUniversal universal(x, y);
  BOOST_CHECK_NO_THROW(pinsettle::checkSupportedModel(oneJoint(universal)));
  universal.axis2 = unit;
  BOOST_CHECK(contains(refusal(oneJoint(universal)), "not orthogonal"));

  // Inside a composite too.
  pinocchio::JointModelComposite composite;
  composite.addJoint(pinocchio::JointModelRX());
  composite.addJoint(revolute);
  BOOST_CHECK(contains(refusal(oneJoint(composite)), "not a unit vector"));
}
