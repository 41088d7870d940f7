//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/stability.hpp"
#include "pinsettle/statics.hpp"
#include "joint-kinds.hpp"

#include "pinsettle/prebuilt.hpp"
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

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
    case Stability::Marginal:
      return "marginal";
    case Stability::Unknown:
    default:
      return "unknown";
    }
  }

  namespace
  {
    // Generalized force of the applied efforts alone at (q, v) (at rest: gravity minus the
    // static force): the joint efforts plus sum_i J_i^T f_i of the external forces. These are
    // mapped by RNEA's backward pass without gravity and inertia, over the kinematics the forces
    // were computed on: the difference of two gravity passes (an RNEA with the forces, gravity
    // alone) costs twice that.
    Eigen::VectorXd appliedForce(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const ForceModel & forces)
    {
      Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
      ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
      forces.computeForces(model, data, q, v, tau, fext);
      if (!forces.hasExternalForces())
        return tau;
      // computeForces ran pinocchio::forwardKinematics at q: data.liMi and the joints' motion
      // subspaces are those of q; fext is in the joints' frames, as RNEA takes it.
      for (pinocchio::JointIndex i = static_cast<pinocchio::JointIndex>(model.njoints) - 1; i > 0;
           --i)
      {
        model.joints[i].jointVelocitySelector(tau).noalias() +=
          data.joints[i].S().matrix().transpose() * fext[i].toVector();
        const pinocchio::JointIndex parent = model.parents[i];
        if (parent > 0)
          fext[parent] += data.liMi[i].act(fext[i]);
      }
      return tau;
    }

    // Below this many degrees of freedom the eigen-decompositions work in fixed-capacity
    // storage: a small mechanism's estimates and assessments otherwise spend much of their time
    // in heap allocations (a fifth of a two-joint arm's whole solve).
    constexpr int kSmallSize = 8;
    template<int MaxN>
    using MatrixN = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, MaxN, MaxN>;
    template<int MaxN>
    using VectorN = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, MaxN, 1>;

    // Eigenvalues (increasing) and the softest direction of K's symmetric part.
    template<int MaxN>
    void decomposeStiffness(const Eigen::MatrixXd & K, StabilityReport & report)
    {
      const MatrixN<MaxN> symmetric = 0.5 * (K + K.transpose());
      Eigen::SelfAdjointEigenSolver<MatrixN<MaxN>> eig(symmetric);
      report.eigenvalues = eig.eigenvalues();
      report.softest_direction = eig.eigenvectors().col(0);
    }
  } // namespace

  bool stiffnessByFiniteDifferences(const pinocchio::Model & model, const ForceModel * forces)
  {
    return (forces != nullptr && !forces->empty() && !forces->hasClosedFormStiffness())
           || hasVaryingMotionSubspace(model);
  }

  Eigen::MatrixXd computeStiffnessMatrix(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(model.nv, model.nv);
    // Pinocchio 4.1's gravity derivatives drop the turning of a motion subspace that varies with
    // its joint's configuration (a composite's parts lose their coupling, a universal joint its
    // second axis's turn): difference gravity there.
    const bool varying = hasVaryingMotionSubspace(model);
    const bool applied = forces != nullptr && !forces->empty();
    if (!varying)
      pinocchio::computeGeneralizedGravityDerivatives(model, data, q, K);
    if (!varying && !applied)
      return K;
    if (!varying && forces->hasClosedFormStiffness())
    {
      forces->addStiffness(model, data, q, K);
      return K;
    }
    // tau_static = g - applied: K = dg/dq - d applied/dq.
    const double h = 1e-6;
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(model.nv), q_plus(model.nq), q_minus(model.nq);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    for (int k = 0; k < model.nv; ++k)
    {
      dq[k] = h;
      pinocchio::integrate(model, q, dq, q_plus);
      pinocchio::integrate(model, q, (-dq).eval(), q_minus);
      dq[k] = 0.;
      if (varying)
        K.col(k) = (computeStaticForce(model, data, q_plus, forces)
                    - computeStaticForce(model, data, q_minus, forces))
                   / (2. * h);
      else
        K.col(k) -= (appliedForce(model, data, q_plus, zero, *forces)
                     - appliedForce(model, data, q_minus, zero, *forces))
                    / (2. * h);
    }
    return K;
  }

  StabilityReport assessStiffness(
    const Eigen::MatrixXd & K, double relative_tolerance, double absolute_tolerance)
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
    if (K.rows() <= kSmallSize)
      decomposeStiffness<kSmallSize>(K, report);
    else
      decomposeStiffness<Eigen::Dynamic>(K, report);
    report.min_eigenvalue = report.eigenvalues[0];
    report.max_abs_eigenvalue = report.eigenvalues.cwiseAbs().maxCoeff();
    report.tolerance = std::max(relative_tolerance * report.max_abs_eigenvalue, absolute_tolerance);
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
    const bool differenced = stiffnessByFiniteDifferences(model, forces);
    return assessStiffness(
      computeStiffnessMatrix(model, data, q, forces), differenced ? 1e-7 : 1e-9,
      computeStiffnessFloor(model, differenced));
  }

  double computeGravityScale(const pinocchio::Model & model)
  {
    double mass = 0., reach = 0., lever = 0.;
    for (std::size_t j = 1; j < model.joints.size(); ++j)
    {
      mass += model.inertias[j].mass();
      reach += model.jointPlacements[j].translation().norm();
      lever = std::max(lever, model.inertias[j].lever().norm());
    }
    return mass * model.gravity.linear().norm() * (reach + lever);
  }

  double computeStiffnessFloor(const pinocchio::Model & model, bool differenced)
  {
    // A central difference of step 1e-6 divides the static force's round-off by it.
    return (differenced ? 1e6 : 1.) * kStiffnessRoundOff * computeGravityScale(model);
  }

  double computeRestEnergy(const StabilityReport & report, const Eigen::VectorXd & tau)
  {
    const Eigen::VectorXd f = report.basis.transpose() * tau;
    if (f.size() == 0)
      return 0.;
    const Eigen::MatrixXd Ks = 0.5 * (report.stiffness + report.stiffness.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Ks);
    const Eigen::VectorXd along = eig.eigenvectors().transpose() * f;
    double energy = 0.;
    for (Eigen::Index k = 0; k < along.size(); ++k)
    {
      const double stiffness = std::max(eig.eigenvalues()[k], report.tolerance);
      if (along[k] == 0.)
        continue;
      if (!(stiffness > 0.))
        return std::numeric_limits<double>::infinity();
      energy += 0.5 * along[k] * along[k] / stiffness;
    }
    return energy;
  }

  namespace
  {
    // Largest |lambda| of A x = lambda M x, with M = L L^T: the eigenvalues of L^-1 A L^-T.
    template<int MaxN>
    double largestGeneralizedEigenvalue(
      const Eigen::MatrixXd & A, const Eigen::LLT<MatrixN<MaxN>> & llt)
    {
      MatrixN<MaxN> B = llt.matrixL().solve(0.5 * (A + A.transpose()));
      B = llt.matrixL().solve(B.transpose()).eval();
      Eigen::SelfAdjointEigenSolver<MatrixN<MaxN>> eig(
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
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
    for (int k = 0; k < model.nv; ++k)
    {
      v[k] = h;
      const Eigen::VectorXd tau_plus = appliedForce(model, data, q, v, *forces);
      v[k] = -h;
      const Eigen::VectorXd tau_minus = appliedForce(model, data, q, v, *forces);
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
    prebuilt::crba(model, data, q);
    const Eigen::MatrixXd M = data.M.selfadjointView<Eigen::Upper>();
    return computeTimeScale(K, M, tau, damped ? &D : nullptr, scale_stiff_modes);
  }

  namespace
  {
    // The modes of K phi = lambda M phi, with M = L L^T: B = L^-1 K L^-T = U Lambda U^T, and
    // Phi = L^-T U is M-orthonormal (Phi^T M = (L U)^T).
    template<int MaxN>
    struct Modes
    {
      MatrixN<MaxN> L;
      Eigen::LLT<MatrixN<MaxN>> llt; // of M (regularised where M is singular)
      VectorN<MaxN> lambda;          // increasing
      MatrixN<MaxN> U;
      VectorN<MaxN> f; // the modal pull Phi^T tau = U^T L^-1 tau

      // |Phi modal|_inf: the joint-space size of a modal vector.
      double jointPull(const VectorN<MaxN> & modal) const
      {
        return L.transpose()
          .template triangularView<Eigen::Upper>()
          .solve(modal)
          .template lpNorm<Eigen::Infinity>();
      }
    };

    template<int MaxN>
    Modes<MaxN> computeModes(
      const Eigen::MatrixXd & K, const Eigen::MatrixXd & mass, const Eigen::VectorXd & tau)
    {
      Modes<MaxN> modes;
      MatrixN<MaxN> M = mass;
      modes.llt.compute(M);
      if (modes.llt.info() != Eigen::Success) // a massless chain end: regularise relative to M
      {
        M.diagonal().array() += 1e-12 * M.diagonal().cwiseAbs().maxCoeff() + 1e-300;
        modes.llt.compute(M);
      }
      modes.L = modes.llt.matrixL();
      const MatrixN<MaxN> & L = modes.L;
      MatrixN<MaxN> B = L.template triangularView<Eigen::Lower>().solve(0.5 * (K + K.transpose()));
      B = L.template triangularView<Eigen::Lower>().solve(B.transpose()).eval();
      Eigen::SelfAdjointEigenSolver<MatrixN<MaxN>> eig(0.5 * (B + B.transpose()));
      modes.lambda = eig.eigenvalues();
      modes.U = eig.eigenvectors();
      modes.f = tau; // in place: a solve into tau's own type would allocate
      L.template triangularView<Eigen::Lower>().solveInPlace(modes.f);
      modes.f = modes.U.transpose() * modes.f;
      return modes;
    }

    // The stiff modes: order[split..] of the modes sorted by |lambda|, to be scaled down to
    // |lambda| = target (split = n: none).
    template<int MaxN>
    struct StiffSet
    {
      Eigen::Matrix<Eigen::Index, Eigen::Dynamic, 1, 0, MaxN, 1> order;
      Eigen::Index split;
      double target = 0.;
    };

    // Soft set: modes by increasing |lambda|, each raising the level (its |lambda| unless it is
    // zero within round-off, and the joint pull of the set so far). The stiff set starts at the
    // first mode more than kStiffGap above the level (they are scaled down to the level), or more
    // than kStiffSpread above the first level (a spread without a gap: a chain of links from 1 mm
    // to 100 m; they are scaled down to kStiffSpread times that). Unstable modes (lambda < 0)
    // count by |lambda|: their growth needs resolving too. scale_stiff_modes = false: none.
    template<int MaxN>
    StiffSet<MaxN> findStiffModes(
      const Modes<MaxN> & modes, double max_abs, double pull_all, bool scale_stiff_modes)
    {
      const VectorN<MaxN> & lambda = modes.lambda;
      const Eigen::Index n = lambda.size();
      StiffSet<MaxN> stiff;
      stiff.order.resize(n);
      std::iota(stiff.order.data(), stiff.order.data() + n, Eigen::Index(0));
      std::sort(stiff.order.data(), stiff.order.data() + n, [&](Eigen::Index a, Eigen::Index b) {
        return std::abs(lambda[a]) < std::abs(lambda[b]);
      });
      stiff.split = n;
      // Eigenvalues below tol and pulls below pull_tol are zero within round-off: they set no
      // level (a level of 1e-9 from a neutral mode would make every real mode 'stiff'). A zero
      // mode's pull is noise from the eigenvectors of a near-degenerate cluster, hence the looser
      // bound.
      const double tol = 1e-12 * std::max(max_abs, pull_all);
      const double pull_tol = std::max(tol, 1e-8 * pull_all);
      double level = 0.;
      double first_level = 0.;
      VectorN<MaxN> soft_modal = VectorN<MaxN>::Zero(n);
      for (Eigen::Index i = 0; i < n; ++i)
      {
        const Eigen::Index k = stiff.order[i];
        const double size = std::abs(lambda[k]);
        if (scale_stiff_modes && level > 0. && size > tol)
        {
          const double cap = kStiffSpread * first_level;
          if (size > kStiffGap * level || size > cap)
          {
            stiff.split = i;
            stiff.target = size > kStiffGap * level ? level : std::max(level, cap);
            break;
          }
        }
        if (size > tol)
          level = std::max(level, size);
        soft_modal += modes.U.col(k) * modes.f[k];
        const double pull = modes.jointPull(soft_modal);
        if (pull > pull_tol)
          level = std::max(level, pull);
        if (first_level == 0.)
          first_level = level;
      }
      return stiff;
    }

    // Slow the stiff set down to its target where the longer step pays for the correction it
    // costs every step; returns omega^2 of the scaled system (omega2 when nothing is scaled).
    template<int MaxN>
    double scaleStiffModes(
      const Modes<MaxN> & modes, const StiffSet<MaxN> & stiff, double omega2, TimeScale & scale)
    {
      const Eigen::Index n = modes.lambda.size();
      if (stiff.split >= n)
        return omega2;
      const Eigen::Index r = n - stiff.split;
      const auto stiffMode = [&](Eigen::Index j) { return stiff.order[stiff.split + j]; };
      VectorN<MaxN> modal = modes.f;
      for (Eigen::Index j = 0; j < r; ++j) // the scaled modes' share of their pull
        modal[stiffMode(j)] *= stiff.target / std::abs(modes.lambda[stiffMode(j)]);
      const double scaled = std::max(stiff.target, modes.jointPull(modes.U * modal));
      // The correction costs every step an nv x nv inverse mass matrix and its product with
      // the r modes (pinocchio::aba alone is O(nv)): keep the scaling only where the longer
      // step it allows pays for that. The steps fall by about the square root of the step's
      // gain (the slow modes, not the step, set how many it takes), hence the square.
      const double gain = std::sqrt(omega2 / scaled);
      const double cost =
        1. + kStiffCostBase + static_cast<double>(n) * static_cast<double>(1 + r) / kStiffCostScale;
      if (!(gain > cost * cost))
        return omega2;
      Eigen::MatrixXd U_s(n, r);
      scale.stiff_masses.resize(r);
      for (Eigen::Index j = 0; j < r; ++j)
      {
        U_s.col(j) = modes.U.col(stiffMode(j));
        scale.stiff_masses[j] = std::abs(modes.lambda[stiffMode(j)]) / stiff.target - 1.;
      }
      scale.stiff_momenta = (modes.L * U_s).transpose();
      return scaled;
    }

    template<int MaxN>
    TimeScale timeScaleOf(
      const Eigen::MatrixXd & K,
      const Eigen::MatrixXd & mass,
      const Eigen::VectorXd & tau,
      const Eigen::MatrixXd * damping,
      bool scale_stiff_modes)
    {
      TimeScale scale;
      const Modes<MaxN> modes = computeModes<MaxN>(K, mass, tau);
      const double max_abs = modes.lambda.cwiseAbs().maxCoeff();
      const double pull_all = modes.jointPull(modes.U * modes.f);
      scale.omega_unscaled = std::sqrt(std::max(max_abs, pull_all));
      const StiffSet<MaxN> stiff = findStiffModes(modes, max_abs, pull_all, scale_stiff_modes);
      const double omega2 = scaleStiffModes(modes, stiff, std::max(max_abs, pull_all), scale);
      scale.omega_max = std::sqrt(omega2);
      if (damping != nullptr)
        scale.damping_rate = largestGeneralizedEigenvalue<MaxN>(*damping, modes.llt);
      const double gamma = scale.damping_rate;
      const double root = std::sqrt(gamma * gamma + 4. * omega2);
      scale.critical_step =
        gamma + root > 0. ? 4. / (gamma + root) : std::numeric_limits<double>::infinity();
      return scale;
    }
  } // namespace

  namespace
  {
    template<int MaxN>
    Eigen::VectorXd solveRankCut(
      const Eigen::MatrixXd & K, const Eigen::VectorXd & b, double threshold)
    {
      // The threshold must be set before the decomposition: compute() takes the rank from it to
      // build Z, and a cut set afterwards made solve() apply Z's coefficients for a rank they
      // were never computed for (uninitialised memory: a Newton step 25 times too long).
      Eigen::CompleteOrthogonalDecomposition<MatrixN<MaxN>> cod(K.rows(), K.cols());
      cod.setThreshold(threshold);
      cod.compute(K);
      const VectorN<MaxN> rhs = b; // a solve on b's own type would allocate its temporaries
      const VectorN<MaxN> x = cod.solve(rhs);
      return x;
    }
  } // namespace

  Eigen::VectorXd solveWithRankCut(
    const Eigen::MatrixXd & K, const Eigen::VectorXd & b, double threshold)
  {
    if (K.rows() <= kSmallSize && K.cols() <= kSmallSize)
      return solveRankCut<kSmallSize>(K, b, threshold);
    return solveRankCut<Eigen::Dynamic>(K, b, threshold);
  }

  TimeScale computeTimeScale(
    const Eigen::MatrixXd & K,
    const Eigen::MatrixXd & mass,
    const Eigen::VectorXd & tau,
    const Eigen::MatrixXd * damping,
    bool scale_stiff_modes)
  {
    if (K.rows() <= kSmallSize)
      return timeScaleOf<kSmallSize>(K, mass, tau, damping, scale_stiff_modes);
    return timeScaleOf<Eigen::Dynamic>(K, mass, tau, damping, scale_stiff_modes);
  }

} // namespace pinsettle
