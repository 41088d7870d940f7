//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/stability.hpp"
#include "pinsettle/solver.hpp"

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>

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

  namespace
  {
    // Largest |lambda| of A x = lambda M x, with M = L L^T: the eigenvalues of L^-1 A L^-T.
    double largestGeneralizedEigenvalue(
      const Eigen::MatrixXd & A, const Eigen::LLT<Eigen::MatrixXd> & llt)
    {
      Eigen::MatrixXd B = llt.matrixL().solve(0.5 * (A + A.transpose()));
      B = llt.matrixL().solve(B.transpose()).eval();
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(
        0.5 * (B + B.transpose()), Eigen::EigenvaluesOnly);
      return eig.eigenvalues().cwiseAbs().maxCoeff();
    }
  } // namespace

  TimeScale computeTimeScale(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const Eigen::MatrixXd * stiffness)
  {
    TimeScale scale;
    const Eigen::MatrixXd K =
      stiffness != nullptr ? *stiffness : computeStiffnessMatrix(model, data, q, forces);
    pinocchio::crba(model, data, q);
    Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
    Eigen::LLT<Eigen::MatrixXd> llt(M);
    if (llt.info() != Eigen::Success) // a massless chain end: regularise relative to M's scale
    {
      M.diagonal().array() += 1e-12 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
      llt.compute(M);
    }
    const Eigen::VectorXd pull = llt.solve(computeStaticForce(model, data, q, forces));
    const double omega2 =
      std::max(largestGeneralizedEigenvalue(K, llt), pull.lpNorm<Eigen::Infinity>());
    scale.omega_max = std::sqrt(omega2);
    if (forces != nullptr && forces->hasDamping())
    {
      // D = -d applied / d v by central differences at v = 0 (the damper forces are linear).
      const double h = 1e-6;
      Eigen::MatrixXd D(model.nv, model.nv);
      Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv), tau_plus(model.nv), tau_minus(model.nv);
      ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
      const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
      const auto applied = [&](Eigen::VectorXd & tau) {
        tau.setZero();
        for (pinocchio::Force & f : fext)
          f.setZero();
        forces->computeForces(model, data, q, v, tau, fext);
        if (forces->hasExternalForces()) // the joint torques of fext: rnea without inertia terms
          tau += pinocchio::computeGeneralizedGravity(model, data, q)
                 - pinocchio::rnea(model, data, q, zero, zero, fext);
      };
      for (int k = 0; k < model.nv; ++k)
      {
        v[k] = h;
        applied(tau_plus);
        v[k] = -h;
        applied(tau_minus);
        v[k] = 0.;
        D.col(k) = -(tau_plus - tau_minus) / (2. * h);
      }
      scale.damping_rate = largestGeneralizedEigenvalue(D, llt);
    }
    const double gamma = scale.damping_rate;
    const double root = std::sqrt(gamma * gamma + 4. * omega2);
    scale.critical_step =
      gamma + root > 0. ? 4. / (gamma + root) : std::numeric_limits<double>::infinity();
    return scale;
  }

} // namespace pinsettle
