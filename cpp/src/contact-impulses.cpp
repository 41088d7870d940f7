//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/contact-impulses.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>

namespace pinsettle
{

  namespace
  {
    constexpr int kMaxSweeps = 2000;
    constexpr int kRefreshSweeps = 8;
    // Sweeps from which the active-set solve is tried at every power of two (and at stalls).
    constexpr int kFirstPolishSweep = 64;
    // Changes of the sets in one active-set solve at most.
    constexpr int kPolishRounds = 8;
    // A tangential impulse within this share of its cone's edge is on it (sliding).
    constexpr double kConeEdge = 1e-9;

    // One contact's projected Gauss-Seidel update, in the space of w = Y lambda (the rows'
    // velocities are u = Y^T w + b): the normal impulse, then the tangential one projected onto
    // the disc mu lambda_n; w follows. A row's velocity costs a product of Y's column with w
    // (nv terms), not with all of lambda: go1 lying on its collision points closes more rows
    // than it has degrees of freedom.
    void updateContact(
      const Eigen::Ref<const Eigen::MatrixXd> & Y,
      const Eigen::Ref<const Eigen::VectorXd> & b,
      const Eigen::Vector2d & steps, // 1 / G_nn, 1 / (largest eigenvalue of G_tt)
      double mu,
      Eigen::Index r,
      Eigen::Ref<Eigen::VectorXd> lambda,
      Eigen::VectorXd & w)
    {
      const double old_n = lambda[r + 2];
      const double un = Y.col(r + 2).dot(w) + b[r + 2];
      const double ln = std::max(0., old_n - un * steps[0]);
      lambda[r + 2] = ln;
      if (ln != old_n)
        w.noalias() += (ln - old_n) * Y.col(r + 2);
      const Eigen::Vector2d old_t = lambda.segment<2>(r);
      // No normal impulse, no friction, whatever the sliding velocity: its two products are
      // skipped (most of a step's rows on talos lying on its collision points are pairs that
      // may close but stay open).
      if (ln == 0.)
      {
        if (!old_t.isZero(0.))
        {
          lambda.segment<2>(r).setZero();
          w.noalias() -= Y.middleCols<2>(r) * old_t;
        }
        return;
      }
      const Eigen::Vector2d ut(Y.col(r).dot(w) + b[r], Y.col(r + 1).dot(w) + b[r + 1]);
      // A projected gradient step of length 1 / (largest eigenvalue of the 2 x 2 block): its
      // fixed point is Coulomb's law. A Newton step on the block (G_tt^-1) projected onto the
      // disc is not: on a box held by four corners it stopped at forces that let it creep.
      Eigen::Vector2d lt = old_t - ut * steps[1];
      const double radius = mu * ln;
      const double norm = lt.norm();
      if (norm > radius)
        lt *= norm > 0. ? radius / norm : 0.;
      lambda.segment<2>(r) = lt;
      if (lt != old_t)
        w.noalias() += Y.middleCols<2>(r) * (lt - old_t);
    }

    // The step lengths of each contact's update (updateContact) and of each unilateral row's
    // (1 / G_rr), from Y's columns; 0 for a row that moves nothing.
    void computeSteps(
      const Eigen::Ref<const Eigen::MatrixXd> & Y, Eigen::Index contacts, Eigen::Matrix2Xd & steps)
    {
      const auto inverse = [](double x) { return x > 0. ? 1. / x : 0.; };
      for (Eigen::Index k = 0; k < contacts; ++k)
      {
        const Eigen::Index r = 3 * k;
        const double a = Y.col(r).squaredNorm(), c = Y.col(r + 1).squaredNorm();
        const double off = Y.col(r).dot(Y.col(r + 1));
        const double largest = 0.5 * (a + c) + std::sqrt(0.25 * (a - c) * (a - c) + off * off);
        steps.col(k) << inverse(Y.col(r + 2).squaredNorm()), inverse(largest);
      }
      for (Eigen::Index r = 3 * contacts; r < Y.cols(); ++r)
        steps.col(r - 2 * contacts) << inverse(Y.col(r).squaredNorm()), 0.;
    }

    using ConstMatrixRef = const Eigen::Ref<const Eigen::MatrixXd> &;
    using ConstVectorRef = const Eigen::Ref<const Eigen::VectorXd> &;

    // A contact's or a unilateral row's set in the active-set solve.
    enum Set : signed char
    {
      kOpen,  // no impulse
      kStick, // closed, the contact does not slide (a unilateral row: closed)
      kSlide  // closed, the tangential impulse on its cone's edge along slide's direction
    };

    // How far a normal or unilateral row of impulse l and velocity u breaks Signorini's law.
    double normalError(double l, double u)
    {
      return l > 0. ? std::abs(u) : std::max(0., -u);
    }

    // How far a contact of tangential impulse lt and velocity ut breaks Coulomb's law for a
    // cone of radius mu ln: inside, it must not slide; on the edge, only against its friction.
    double frictionError(
      const Eigen::Vector2d & lt, const Eigen::Vector2d & ut, double ln, double mu)
    {
      if (!(ln > 0.))
        return 0.;
      const double norm = lt.norm();
      if (norm < mu * ln * (1. - kConeEdge))
        return ut.norm();
      const Eigen::Vector2d d = lt / norm;
      const double along = ut.dot(d);
      return (ut - along * d).norm() + std::max(0., along);
    }

    // work.u = Y^T Y lambda + b.
    void computeRowVelocities(
      ConstMatrixRef Y, ConstVectorRef b, ConstVectorRef lambda, ImpulseWorkspace & work)
    {
      work.y_lambda.noalias() = Y * lambda;
      work.u = b;
      work.u.noalias() += Y.transpose() * work.y_lambda;
    }

    // The sets lambda shows: closed where it pushes, sliding where a contact's tangential
    // impulse is on its cone's edge.
    void takeSets(ConstVectorRef friction, ConstVectorRef lambda, ImpulseWorkspace & work)
    {
      const Eigen::Index contacts = friction.size();
      const Eigen::Index rows = lambda.size();
      work.set.assign(static_cast<std::size_t>(contacts + rows - 3 * contacts), kOpen);
      work.slide.resize(2, contacts);
      for (Eigen::Index k = 0; k < contacts; ++k)
      {
        const double ln = lambda[3 * k + 2];
        if (!(ln > 0.))
          continue;
        const Eigen::Vector2d lt = lambda.segment<2>(3 * k);
        const bool edge = lt.norm() >= friction[k] * ln * (1. - kConeEdge) && lt.norm() > 0.;
        work.set[static_cast<std::size_t>(k)] = edge ? kSlide : kStick;
        if (edge)
          work.slide.col(k) = lt.normalized();
      }
      for (Eigen::Index r = 3 * contacts; r < rows; ++r)
        if (lambda[r] > 0.)
          work.set[static_cast<std::size_t>(r - 2 * contacts)] = kStick;
    }

    // The unknowns and equations of the sets: a closed row's impulse, a sticking contact's
    // tangential ones (those that move something), a sliding contact's normal impulse with its
    // friction mu along slide; the number of unknowns.
    Eigen::Index assembleUnknowns(
      ConstMatrixRef Y, ConstVectorRef friction, Eigen::Index rows, ImpulseWorkspace & work)
    {
      const Eigen::Index contacts = friction.size();
      work.basis.setZero(rows, rows);
      work.equations.clear();
      Eigen::Index m = 0;
      // An unknown impulse on row r, whose velocity is held at zero.
      const auto hold = [&work, &m](Eigen::Index r) {
        work.basis(r, m++) = 1.;
        work.equations.push_back(r);
      };
      for (Eigen::Index k = 0; k < contacts; ++k)
      {
        const Set set = static_cast<Set>(work.set[static_cast<std::size_t>(k)]);
        const Eigen::Index r = 3 * k;
        if (set == kSlide)
          work.basis.col(m).segment<2>(r) = friction[k] * work.slide.col(k);
        if (set != kOpen)
          hold(r + 2);
        for (Eigen::Index t = r; set == kStick && t < r + 2; ++t)
          if (Y.col(t).squaredNorm() > 0.)
            hold(t);
      }
      for (Eigen::Index r = 3 * contacts; r < rows; ++r)
        if (work.set[static_cast<std::size_t>(r - 2 * contacts)] != kOpen)
          hold(r);
      return m;
    }

    // work.trial: the impulses of the sets that hold the equations' rows at rest (least norm:
    // redundant contacts share their load).
    void solveSets(
      ConstMatrixRef Y, ConstVectorRef b, ConstVectorRef friction, ImpulseWorkspace & work)
    {
      const Eigen::Index rows = b.size();
      const Eigen::Index m = assembleUnknowns(Y, friction, rows, work);
      work.trial.setZero(rows);
      if (m == 0)
        return;
      const auto n = static_cast<Eigen::Index>(work.equations.size());
      work.y_basis.noalias() = Y * work.basis.leftCols(m);
      work.system.resize(n, m);
      work.rhs.resize(n);
      for (Eigen::Index e = 0; e < n; ++e)
      {
        const Eigen::Index r = work.equations[static_cast<std::size_t>(e)];
        work.system.row(e).noalias() = Y.col(r).transpose() * work.y_basis;
        work.rhs[e] = -b[r];
      }
      work.x = work.system.completeOrthogonalDecomposition().solve(work.rhs);
      work.trial.noalias() = work.basis.leftCols(m) * work.x;
    }

    // A contact's set changed for what its trial impulses and velocities show: whether it was.
    bool reviseContact(
      Eigen::Index k, double mu, ConstVectorRef trial, double tol, ImpulseWorkspace & work)
    {
      auto & set = work.set[static_cast<std::size_t>(k)];
      const Eigen::Index r = 3 * k;
      const Eigen::Vector2d ut = work.u.segment<2>(r), lt = trial.segment<2>(r);
      if (set == kOpen)
      {
        if (work.u[r + 2] >= -tol)
          return false;
        set = kStick;
        return true;
      }
      if (trial[r + 2] < 0.)
        set = kOpen;
      else if (set == kStick && lt.norm() > mu * trial[r + 2] * (1. + kConeEdge))
        set = kSlide, work.slide.col(k) = lt.normalized();
      else if (set == kSlide && ut.dot(work.slide.col(k)) > tol)
        set = kStick;
      else if (set == kSlide && frictionError(lt, ut, trial[r + 2], mu) > tol)
        work.slide.col(k) = -ut.normalized();
      else
        return false;
      return true;
    }

    // The sets changed for the trial: rows that push with a negative impulse open, open rows
    // that close close, contacts pushed out of their cones slide, sliding contacts whose
    // velocity turned stick; where none of these, the sticking contact that slides most is let
    // slide against its velocity (its rows' equations had no exact solution). Whether any
    // changed.
    bool reviseSets(
      ConstVectorRef friction, ConstVectorRef trial, double tol, ImpulseWorkspace & work)
    {
      const Eigen::Index contacts = friction.size();
      bool changed = false;
      for (Eigen::Index k = 0; k < contacts; ++k)
        changed = reviseContact(k, friction[k], trial, tol, work) || changed;
      for (Eigen::Index r = 3 * contacts; r < trial.size(); ++r)
      {
        auto & set = work.set[static_cast<std::size_t>(r - 2 * contacts)];
        const bool flip = set == kOpen ? work.u[r] < -tol : trial[r] < 0.;
        if (flip)
          set = set == kOpen ? kStick : kOpen;
        changed = changed || flip;
      }
      if (changed)
        return true;
      Eigen::Index worst = -1;
      double most = tol;
      for (Eigen::Index k = 0; k < contacts; ++k)
        if (
          work.set[static_cast<std::size_t>(k)] == kStick && work.u.segment<2>(3 * k).norm() > most)
          worst = k, most = work.u.segment<2>(3 * k).norm();
      if (worst < 0)
        return false;
      work.set[static_cast<std::size_t>(worst)] = kSlide;
      work.slide.col(worst) = -work.u.segment<2>(3 * worst).normalized();
      return true;
    }

    // Whether impulses are ones the contacts can give, to round-off: normal and unilateral ones
    // that push, tangential ones inside their cones (a sticking contact's are solved for freely,
    // and go1 lying on its trunk and feet got one 5 % outside).
    bool isAdmissible(ConstVectorRef friction, ConstVectorRef trial)
    {
      const double floor = 1e-9 * trial.lpNorm<Eigen::Infinity>();
      for (Eigen::Index k = 0; k < friction.size(); ++k)
      {
        const Eigen::Index r = 3 * k;
        if (trial[r + 2] < -floor)
          return false;
        if (
          trial.segment<2>(r).norm()
          > friction[k] * std::max(trial[r + 2], 0.) * (1. + kConeEdge) + floor)
          return false;
      }
      for (Eigen::Index r = 3 * friction.size(); r < trial.size(); ++r)
        if (trial[r] < -floor)
          return false;
      return true;
    }

    // The active-set solve from the sets lambda shows: whether it found impulses that keep
    // every law to tol (then lambda and work.w hold them).
    bool polishImpulses(
      ConstMatrixRef Y,
      ConstVectorRef b,
      ConstVectorRef friction,
      Eigen::Ref<Eigen::VectorXd> lambda,
      ImpulseWorkspace & work,
      double tol)
    {
      takeSets(friction, lambda, work);
      for (int round = 0; round < kPolishRounds; ++round)
      {
        solveSets(Y, b, friction, work);
        const double residual = computeImpulseResidual(Y, b, friction, work.trial, work);
        if (residual <= tol && isAdmissible(friction, work.trial))
        {
          // What round-off leaves below zero on an open row moves nothing worth keeping.
          for (Eigen::Index k = 0; k < friction.size(); ++k)
            if (work.trial[3 * k + 2] < 0.)
              work.trial.segment<3>(3 * k).setZero();
          for (Eigen::Index r = 3 * friction.size(); r < work.trial.size(); ++r)
            work.trial[r] = std::max(0., work.trial[r]);
          lambda = work.trial;
          work.w.noalias() = Y * lambda;
          return true;
        }
        if (!reviseSets(friction, work.trial, tol, work))
          return false;
      }
      return false;
    }

    // One projected Gauss-Seidel sweep over the contacts, then the unilateral rows.
    void sweepOnce(
      ConstMatrixRef Y,
      ConstVectorRef b,
      ConstVectorRef friction,
      Eigen::Ref<Eigen::VectorXd> lambda,
      ImpulseWorkspace & work)
    {
      const Eigen::Index contacts = friction.size();
      for (Eigen::Index k = 0; k < contacts; ++k)
        updateContact(Y, b, work.steps.col(k), friction[k], 3 * k, lambda, work.w);
      for (Eigen::Index r = 3 * contacts; r < lambda.size(); ++r)
      {
        const double old = lambda[r];
        const double step = work.steps(0, r - 2 * contacts);
        lambda[r] = std::max(0., old - (Y.col(r).dot(work.w) + b[r]) * step);
        work.w.noalias() += (lambda[r] - old) * Y.col(r);
      }
    }

    bool isPowerOfTwo(int n)
    {
      return (n & (n - 1)) == 0;
    }
  } // namespace

  double computeImpulseResidual(
    ConstMatrixRef Y,
    ConstVectorRef b,
    ConstVectorRef friction,
    ConstVectorRef lambda,
    ImpulseWorkspace & work)
  {
    computeRowVelocities(Y, b, lambda, work);
    const Eigen::Index contacts = friction.size();
    double error = 0.;
    for (Eigen::Index k = 0; k < contacts; ++k)
    {
      const Eigen::Index r = 3 * k;
      const double ln = lambda[r + 2];
      error = std::max(error, normalError(ln, work.u[r + 2]));
      error =
        std::max(error, frictionError(lambda.segment<2>(r), work.u.segment<2>(r), ln, friction[k]));
    }
    for (Eigen::Index r = 3 * contacts; r < lambda.size(); ++r)
      error = std::max(error, normalError(lambda[r], work.u[r]));
    return error;
  }

  int solveContactImpulses(
    ConstMatrixRef Y,
    ConstVectorRef b,
    ConstVectorRef friction,
    Eigen::Ref<Eigen::VectorXd> lambda,
    ImpulseWorkspace & work,
    double round_off)
  {
    const Eigen::Index contacts = friction.size();
    const Eigen::Index updates = contacts + (lambda.size() - 3 * contacts);
    if (work.steps.cols() < updates)
      work.steps.resize(2, updates);
    computeSteps(Y, contacts, work.steps);
    const double tol = std::max(kImpulseTolerance * b.lpNorm<Eigen::Infinity>(), round_off);
    work.w.noalias() = Y * lambda;
    bool stalled_before = false;
    for (int sweep = 1; sweep <= kMaxSweeps; ++sweep)
    {
      work.w_sweep = work.w;
      sweepOnce(Y, b, friction, lambda, work);
      // The running sum drifts from Y lambda by round-off, sweep after sweep: made exact again
      // every few sweeps (left to drift, a ball rolling down a slope veered off sideways).
      if (sweep % kRefreshSweeps == 0)
        work.w.noalias() = Y * lambda;
      // A sweep that no longer moves the velocities may be the answer (impulses that trade load
      // between redundant contacts change nothing) or a plateau the sweeps leave later.
      const double change = (work.w - work.w_sweep).lpNorm<Eigen::Infinity>();
      const bool stalled = change <= 1e-11 * work.w.lpNorm<Eigen::Infinity>() || change == 0.;
      const bool polish_due =
        (stalled && !stalled_before) || (sweep >= kFirstPolishSweep && isPowerOfTwo(sweep));
      stalled_before = stalled;
      if (!stalled && !polish_due)
        continue;
      if (computeImpulseResidual(Y, b, friction, lambda, work) <= tol)
      {
        work.w = work.y_lambda;
        return sweep;
      }
      if (polish_due && polishImpulses(Y, b, friction, lambda, work, tol))
        return sweep;
    }
    work.w.noalias() = Y * lambda;
    return kMaxSweeps;
  }

} // namespace pinsettle
