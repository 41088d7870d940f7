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

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

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

    bool hasCompositeJoint(const pinocchio::Model & model)
    {
      for (std::size_t j = 1; j < model.joints.size(); ++j)
        if (model.joints[j].shortname() == "JointModelComposite")
          return true;
      return false;
    }
  } // namespace

  bool stiffnessByFiniteDifferences(const pinocchio::Model & model, const ForceModel * forces)
  {
    return (forces != nullptr && !forces->empty()) || hasCompositeJoint(model);
  }

  Eigen::MatrixXd computeStiffnessMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(model.nv, model.nv);
    // Pinocchio 4.1's gravity derivatives drop the coupling between the parts of a composite
    // joint (a composite of RX and RY gets a triangular block): difference gravity there.
    const bool composite = hasCompositeJoint(model);
    const bool applied = forces != nullptr && !forces->empty();
    if (!composite)
      pinocchio::computeGeneralizedGravityDerivatives(model, data, q, K);
    if (!composite && !applied)
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
      if (composite)
        K.col(k) = (computeStaticForce(model, data, q_plus, forces)
                    - computeStaticForce(model, data, q_minus, forces))
                   / (2. * h);
      else
        K.col(k) -=
          (appliedForce(model, data, q_plus, *forces) - appliedForce(model, data, q_minus, *forces))
          / (2. * h);
    }
    return K;
  }

  StabilityReport assessStiffness(const Eigen::MatrixXd & K, double relative_tolerance)
  {
    StabilityReport report;
    report.stiffness = K;
    report.basis = Eigen::MatrixXd::Identity(K.rows(), K.cols());
    if (K.rows() == 0)
    {
      report.verdict = Stability::Neutral;
      report.eigenvalues.resize(0);
      report.softest_direction.resize(0);
      return report;
    }
    const Eigen::MatrixXd symmetric = 0.5 * (K + K.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(symmetric);
    report.eigenvalues = eig.eigenvalues();
    report.softest_direction = eig.eigenvectors().col(0);
    report.min_eigenvalue = report.eigenvalues[0];
    report.max_abs_eigenvalue = report.eigenvalues.cwiseAbs().maxCoeff();
    report.tolerance = relative_tolerance * report.max_abs_eigenvalue;
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

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    return assessStiffness(
      computeStiffnessMatrix(model, data, q, forces),
      stiffnessByFiniteDifferences(model, forces) ? 1e-7 : 1e-9);
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

  Eigen::MatrixXd computeDampingMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(model.nv, model.nv);
    if (forces == nullptr || !forces->hasDamping())
      return D;
    // D = -d applied / d v by central differences at v = 0 (the damper forces are linear).
    const double h = 1e-6;
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv), tau_plus(model.nv), tau_minus(model.nv);
    ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    const auto applied = [&](Eigen::VectorXd & tau) {
      tau.setZero();
      for (pinocchio::Force & force : fext)
        force.setZero();
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
    return D;
  }

  TimeScale computeTimeScale(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    bool scale_stiff_modes,
    const Eigen::MatrixXd * stiffness)
  {
    const Eigen::MatrixXd K =
      stiffness != nullptr ? *stiffness : computeStiffnessMatrix(model, data, q, forces);
    const Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
    const bool damped = forces != nullptr && forces->hasDamping();
    const Eigen::MatrixXd D =
      damped ? computeDampingMatrix(model, data, q, forces) : Eigen::MatrixXd();
    pinocchio::crba(model, data, q);
    const Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
    return computeTimeScale(K, M, tau, damped ? &D : nullptr, scale_stiff_modes);
  }

  TimeScale computeTimeScale(
    const Eigen::MatrixXd & K,
    const Eigen::MatrixXd & mass,
    const Eigen::VectorXd & tau,
    const Eigen::MatrixXd * damping,
    bool scale_stiff_modes)
  {
    TimeScale scale;
    const Eigen::Index n = K.rows();
    Eigen::MatrixXd M = mass;
    Eigen::LLT<Eigen::MatrixXd> llt(M);
    if (llt.info() != Eigen::Success) // a massless chain end: regularise relative to M's scale
    {
      M.diagonal().array() += 1e-12 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
      llt.compute(M);
    }
    const Eigen::MatrixXd L = llt.matrixL();
    // Modes: K phi = lambda M phi. With B = L^-1 K L^-T = U Lambda U^T, Phi = L^-T U is
    // M-orthonormal, Phi^T M = (L U)^T, and the modal pull is f = Phi^T tau = U^T L^-1 tau.
    Eigen::MatrixXd B = L.triangularView<Eigen::Lower>().solve(0.5 * (K + K.transpose()));
    B = L.triangularView<Eigen::Lower>().solve(B.transpose()).eval();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (B + B.transpose()));
    const Eigen::VectorXd & lambda = eig.eigenvalues(); // increasing
    const Eigen::MatrixXd & U = eig.eigenvectors();
    const Eigen::VectorXd f = U.transpose() * L.triangularView<Eigen::Lower>().solve(tau);
    const auto jointPull = [&](const Eigen::VectorXd & modal) { // |Phi modal|_inf
      return L.transpose().triangularView<Eigen::Upper>().solve(modal).lpNorm<Eigen::Infinity>();
    };
    const double max_abs = lambda.cwiseAbs().maxCoeff();
    const double pull_all = jointPull(U * f);
    scale.omega_unscaled = std::sqrt(std::max(max_abs, pull_all));

    // Soft set: modes by increasing |lambda|, each raising the level (its |lambda| unless it is
    // zero within round-off, and the joint pull of the set so far). The stiff set starts at the
    // first mode more than kStiffGap above the level (they are scaled down to the level), or more
    // than kStiffSpread above the first level (a spread without a gap: a chain of links from 1 mm
    // to 100 m; they are scaled down to kStiffSpread times that). Unstable modes (lambda < 0)
    // count by |lambda|: their growth needs resolving too.
    std::vector<Eigen::Index> order(static_cast<std::size_t>(n));
    std::iota(order.begin(), order.end(), Eigen::Index(0));
    std::sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
      return std::abs(lambda[a]) < std::abs(lambda[b]);
    });
    // Eigenvalues below tol and pulls below pull_tol are zero within round-off: they set no
    // level (a level of 1e-9 from a neutral mode would make every real mode 'stiff'). A zero
    // mode's pull is noise from the eigenvectors of a near-degenerate cluster, hence the looser
    // bound.
    const double tol = 1e-12 * std::max(max_abs, pull_all);
    const double pull_tol = std::max(tol, 1e-8 * pull_all);
    std::size_t split = order.size();
    double level = 0.;
    double first_level = 0.;
    double target = 0.;
    Eigen::VectorXd soft_modal = Eigen::VectorXd::Zero(n);
    for (std::size_t i = 0; i < order.size(); ++i)
    {
      const Eigen::Index k = order[i];
      const double size = std::abs(lambda[k]);
      if (scale_stiff_modes && level > 0. && size > tol)
      {
        const double cap = kStiffSpread * first_level;
        if (size > kStiffGap * level || size > cap)
        {
          split = i;
          target = size > kStiffGap * level ? level : std::max(level, cap);
          break;
        }
      }
      if (size > tol)
        level = std::max(level, size);
      soft_modal += U.col(k) * f[k];
      const double pull = jointPull(soft_modal);
      if (pull > pull_tol)
        level = std::max(level, pull);
      if (first_level == 0.)
        first_level = level;
    }
    double omega2 = std::max(max_abs, pull_all);
    if (split < order.size())
    {
      const Eigen::Index r = n - static_cast<Eigen::Index>(split);
      const auto stiffMode = [&](Eigen::Index j) {
        return order[split + static_cast<std::size_t>(j)];
      };
      Eigen::VectorXd modal = f;
      for (Eigen::Index j = 0; j < r; ++j) // the scaled modes' share of their pull
        modal[stiffMode(j)] *= target / std::abs(lambda[stiffMode(j)]);
      const double scaled = std::max(target, jointPull(U * modal));
      // The correction costs every step an nv x nv inverse mass matrix and its product with
      // the r modes (pinocchio::aba alone is O(nv)): keep the scaling only where the longer
      // step it allows pays for that. The steps fall by about the square root of the step's
      // gain (the slow modes, not the step, set how many it takes), hence the square.
      const double gain = std::sqrt(omega2 / scaled);
      const double cost =
        1. + kStiffCostBase + static_cast<double>(n) * static_cast<double>(1 + r) / kStiffCostScale;
      if (gain > cost * cost)
      {
        Eigen::MatrixXd U_s(n, r);
        scale.stiff_masses.resize(r);
        for (Eigen::Index j = 0; j < r; ++j)
        {
          U_s.col(j) = U.col(stiffMode(j));
          scale.stiff_masses[j] = std::abs(lambda[stiffMode(j)]) / target - 1.;
        }
        scale.stiff_momenta = (L * U_s).transpose();
        omega2 = scaled;
      }
    }
    scale.omega_max = std::sqrt(omega2);
    if (damping != nullptr)
      scale.damping_rate = largestGeneralizedEigenvalue(*damping, llt);
    const double gamma = scale.damping_rate;
    const double root = std::sqrt(gamma * gamma + 4. * omega2);
    scale.critical_step =
      gamma + root > 0. ? 4. / (gamma + root) : std::numeric_limits<double>::infinity();
    return scale;
  }

} // namespace pinsettle
