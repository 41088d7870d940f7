//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/stability.hpp"
#include "pinsettle/solver.hpp"

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>

namespace pinsettle
{

  const char * toString(Stability stability)
  {
    switch (stability)
    {
    case Stability::Stable:
      return "stable";
    case Stability::Neutral:
      return "neutral";
    case Stability::Unstable:
      return "unstable";
    case Stability::Unknown:
    default:
      return "unknown";
    }
  }

  namespace
  {
    // Generalized force of the applied efforts alone at rest: static force minus gravity.
    Eigen::VectorXd appliedForce(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const ForceModel & forces)
    {
      const Eigen::VectorXd gravity = pinocchio::computeGeneralizedGravity(model, data, q);
      return gravity - computeStaticForce(model, data, q, &forces);
    }
  } // namespace

  Eigen::MatrixXd computeStiffnessMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(model.nv, model.nv);
    pinocchio::computeGeneralizedGravityDerivatives(model, data, q, K);
    if (forces == nullptr || forces->empty())
      return K;
    // tau_static = g - applied: K = dg/dq - d applied/dq.
    const double h = 1e-6;
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv), q_plus(model.nq), q_minus(model.nq);
    for (int k = 0; k < model.nv; ++k)
    {
      dq[k] = h;
      pinocchio::integrate(model, q, dq, q_plus);
      pinocchio::integrate(model, q, -dq, q_minus);
      dq[k] = 0.;
      K.col(k) -=
        (appliedForce(model, data, q_plus, *forces) - appliedForce(model, data, q_minus, *forces))
        / (2. * h);
    }
    return K;
  }

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    StabilityReport report;
    report.stiffness = computeStiffnessMatrix(model, data, q, forces);
    const Eigen::MatrixXd & K = report.stiffness;
    const Eigen::MatrixXd symmetric = 0.5 * (K + K.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(symmetric);
    report.eigenvalues = eig.eigenvalues();
    report.softest_direction = eig.eigenvectors().col(0);
    report.min_eigenvalue = report.eigenvalues[0];
    report.max_abs_eigenvalue = report.eigenvalues.cwiseAbs().maxCoeff();
    const bool finite_differences = forces != nullptr && !forces->empty();
    report.tolerance = (finite_differences ? 1e-7 : 1e-9) * report.max_abs_eigenvalue;
    for (Eigen::Index k = 0; k < report.eigenvalues.size(); ++k)
      if (std::abs(report.eigenvalues[k]) <= report.tolerance)
        ++report.neutral_directions;
    if (report.min_eigenvalue < -report.tolerance)
      report.verdict = Stability::Unstable;
    else if (report.neutral_directions > 0)
      report.verdict = Stability::Neutral;
    else
      report.verdict = Stability::Stable;
    return report;
  }

} // namespace pinsettle
