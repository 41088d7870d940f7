//
// Copyright (c) 2026 pinsettle contributors
//

// constraintDynamics is marked "unsupported, the API will change"; it is the constrained
// forward dynamics Pinocchio ships, and only this file calls it (through prebuilt-constrained.hpp:
// pinocchio_default's instantiation, not compiled here).
#define PINOCCHIO_DISABLE_UNSUPPORTED_WARNINGS

#include "pinsettle/loops.hpp"
#include "pinsettle/statics.hpp"
#include "loop-stepper.hpp"
#include "prebuilt-constrained.hpp"

#include <pinocchio/algorithm/aba.hpp>
#include "pinsettle/prebuilt.hpp"
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pinsettle
{

  const char * toString(LoopKind kind)
  {
    return kind == LoopKind::Point ? "point" : "frame";
  }

  LoopConstraints::LoopConstraints(const pinocchio::Model & model)
  : model_(model)
  {
  }

  void LoopConstraints::addLoop(
    pinocchio::FrameIndex frame_a,
    const Eigen::Vector3d & point_a,
    pinocchio::FrameIndex frame_b,
    const Eigen::Vector3d & point_b,
    LoopKind kind,
    const std::string & name)
  {
    const std::string what = name.empty() ? "loop #" + std::to_string(loops_.size() + 1) : name;
    for (const pinocchio::FrameIndex frame : {frame_a, frame_b})
      if (frame >= model_.frames.size())
      {
        std::ostringstream msg;
        msg << what << ": frame index " << frame << " is out of range (the model has "
            << model_.frames.size() << " frames)";
        throw std::invalid_argument(msg.str());
      }
    if (!point_a.allFinite() || !point_b.allFinite())
      throw std::invalid_argument(what + ": every entry of the points must be finite");
    const pinocchio::Frame & fa = model_.frames[frame_a];
    const pinocchio::Frame & fb = model_.frames[frame_b];
    if (fa.parentJoint == fb.parentJoint)
      throw std::invalid_argument(
        what + ": both ends ('" + fa.name + "' and '" + fb.name + "') are on the same rigid body ("
        + (fa.parentJoint == 0 ? std::string("the world") : "the body of joint '" + model_.names[fa.parentJoint] + "'")
        + "); such a loop holds nothing");
    // Frames of a fixed link sit on their parent joint at a fixed placement.
    const pinocchio::SE3 offset_a(Eigen::Matrix3d::Identity(), point_a);
    const pinocchio::SE3 offset_b(Eigen::Matrix3d::Identity(), point_b);
    loops_.push_back(
      Loop{
        what, fa.parentJoint, fa.placement * offset_a, fb.parentJoint, fb.placement * offset_b,
        kind});
    rows_ += loops_.back().rows();
  }

  void LoopConstraints::addCoupling(
    pinocchio::JointIndex follower,
    pinocchio::JointIndex leader,
    double multiplier,
    double offset,
    const std::string & name)
  {
    const std::string what =
      name.empty() ? "coupling #" + std::to_string(couplings_.size() + 1) : name;
    for (const pinocchio::JointIndex joint : {follower, leader})
    {
      if (joint == 0 || joint >= static_cast<pinocchio::JointIndex>(model_.njoints))
      {
        std::ostringstream msg;
        msg << what << ": joint index " << joint << " is out of range (1 to " << model_.njoints - 1
            << ")";
        throw std::invalid_argument(msg.str());
      }
      if (model_.nqs[joint] != 1 || model_.nvs[joint] != 1)
        throw std::invalid_argument(
          what + ": joint '" + model_.names[joint] + "' (" + model_.joints[joint].shortname()
          + ") has " + std::to_string(model_.nqs[joint]) + " configuration entries and "
          + std::to_string(model_.nvs[joint])
          + " velocities; a coupling takes 1-DoF joints with one of each (revolute, prismatic, "
            "helical)");
    }
    if (follower == leader)
      throw std::invalid_argument(
        what + ": joint '" + model_.names[follower] + "' cannot follow itself");
    if (!std::isfinite(multiplier) || !std::isfinite(offset))
      throw std::invalid_argument(what + ": the multiplier and the offset must be finite");
    couplings_.push_back(
      JointCoupling{
        what, follower, leader, model_.idx_qs[follower], model_.idx_vs[follower],
        model_.idx_qs[leader], model_.idx_vs[leader], multiplier, offset});
    rows_ += 1;
  }

  namespace
  {
    // World placement of a loop end from the kinematics in data.oMi.
    pinocchio::SE3 endPlacement(
      const pinocchio::Data & data, pinocchio::JointIndex joint, const pinocchio::SE3 & placement)
    {
      return data.oMi[joint] * placement;
    }

    // Loop errors, and the Jacobian when J is given; kinematics from q (a computeJointJacobians
    // pass with the Jacobian, forwardKinematics without). work is a 6 x nv scratch.
    void evaluateLoops(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const LoopConstraints & loops,
      const Eigen::VectorXd & q,
      Eigen::VectorXd & error,
      Eigen::MatrixXd * J,
      pinocchio::Data::Matrix6x & work_a,
      pinocchio::Data::Matrix6x & work_b)
    {
      const bool kinematics = !loops.loops().empty(); // couplings need none
      if (kinematics && J != nullptr)
        pinocchio::computeJointJacobians(model, data, q);
      else if (kinematics)
        pinocchio::forwardKinematics(model, data, q);
      Eigen::Index row = 0;
      for (const Loop & loop : loops.loops())
      {
        const pinocchio::SE3 Ma = endPlacement(data, loop.joint_a, loop.placement_a);
        const pinocchio::SE3 Mb = endPlacement(data, loop.joint_b, loop.placement_b);
        error.segment<3>(row) = Ma.translation() - Mb.translation();
        if (loop.kind == LoopKind::Frame)
          error.segment<3>(row + 3) =
            pinocchio::log3(Eigen::Matrix3d(Ma.rotation() * Mb.rotation().transpose()));
        if (J != nullptr)
        {
          // WORLD Jacobians: spatial velocity at the world origin; a point p moves with
          // v + w x p.
          work_a.setZero();
          work_b.setZero();
          if (loop.joint_a > 0)
            pinocchio::getJointJacobian(model, data, loop.joint_a, pinocchio::WORLD, work_a);
          if (loop.joint_b > 0)
            pinocchio::getJointJacobian(model, data, loop.joint_b, pinocchio::WORLD, work_b);
          const Eigen::Matrix3d skew_a = pinocchio::skew(Ma.translation());
          const Eigen::Matrix3d skew_b = pinocchio::skew(Mb.translation());
          J->middleRows<3>(row).noalias() =
            work_a.topRows<3>() - skew_a * work_a.bottomRows<3>() - work_b.topRows<3>();
          J->middleRows<3>(row).noalias() += skew_b * work_b.bottomRows<3>();
          if (loop.kind == LoopKind::Frame)
            J->middleRows<3>(row + 3) = work_a.bottomRows<3>() - work_b.bottomRows<3>();
        }
        row += loop.rows();
      }
      // Couplings: linear in q, a constant Jacobian row.
      for (const JointCoupling & c : loops.couplings())
      {
        error[row] = q[c.iq_follower] - c.multiplier * q[c.iq_leader] - c.offset;
        if (J != nullptr)
        {
          J->row(row).setZero();
          (*J)(row, c.iv_follower) = 1.;
          (*J)(row, c.iv_leader) -= c.multiplier;
        }
        ++row;
      }
    }

    // Rank of a decomposition: singular values above 1e-9 of the largest (redundant equations,
    // a planar loop's out-of-plane row, fall below).
    Eigen::Index svdRank(const Eigen::JacobiSVD<Eigen::MatrixXd> & svd)
    {
      const Eigen::VectorXd & s = svd.singularValues();
      if (s.size() == 0 || s[0] <= 0.)
        return 0;
      Eigen::Index r = 0;
      while (r < s.size() && s[r] > 1e-9 * s[0])
        ++r;
      return r;
    }

    // Least-norm solution of J x = b from an SVD of J.
    void solveLeastNorm(
      const Eigen::JacobiSVD<Eigen::MatrixXd> & svd,
      Eigen::Index rank,
      const Eigen::VectorXd & b,
      Eigen::VectorXd & x)
    {
      const Eigen::VectorXd c = svd.matrixU().leftCols(rank).transpose() * b;
      x.noalias() = svd.matrixV().leftCols(rank) * c.cwiseQuotient(svd.singularValues().head(rank));
    }

    // A pinned joint's column is zero, but the least-norm step from an SVD puts round-off
    // (1e-17) on it all the same: enough to lift a joint off its stop, or give it a velocity
    // into it, so that it is no longer held and chatters there (Fetch's torso on its upper
    // stop, its step halved 22 times). Pinned entries are copied back exactly.
    void keepPinned(
      const pinocchio::Model & model,
      const Eigen::VectorXd & q,
      const std::vector<Eigen::Index> * pinned,
      Eigen::VectorXd & q_next)
    {
      if (pinned == nullptr)
        return;
      for (const Eigen::Index i : *pinned)
        for (std::size_t j = 1; j < model.joints.size(); ++j)
          if (model.idx_vs[j] == i)
          {
            q_next[model.idx_qs[j]] = q[model.idx_qs[j]];
            break;
          }
    }

    // With stops: the joints on a stop that the step q <- q - dq would push past it, held (added
    // to held, their columns zeroed). Returns whether any was added.
    bool holdPushed(
      const JointStops & stops,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & dq,
      std::vector<Eigen::Index> & held,
      Eigen::MatrixXd & J)
    {
      bool added = false;
      for (const JointStops::Stop & s : stops.stops())
      {
        const bool pushed =
          (q[s.iq] <= s.lower && dq[s.iv] > 0.) || (q[s.iq] >= s.upper && dq[s.iv] < 0.);
        if (pushed && std::find(held.begin(), held.end(), s.iv) == held.end())
        {
          held.push_back(s.iv);
          J.col(s.iv).setZero();
          added = true;
        }
      }
      return added;
    }

    // Gauss-Newton's workspace: the loops' error and Jacobian at q and at a trial q_next, the
    // Jacobian's SVD and the step.
    struct GaussNewtonWork
    {
      GaussNewtonWork(const pinocchio::Model & model, const LoopConstraints & loops)
      : error(loops.rows())
      , error_next(loops.rows())
      , J(loops.rows(), model.nv)
      , dq(model.nv)
      , q_next(model.nq)
      , work_a(6, model.nv)
      , work_b(6, model.nv)
      {
      }

      Eigen::VectorXd error, error_next;
      Eigen::MatrixXd J;
      Eigen::JacobiSVD<Eigen::MatrixXd> svd;
      Eigen::VectorXd dq, q_next;
      pinocchio::Data::Matrix6x work_a, work_b;
    };

    // What a projection onto the loops keeps still: pinned joints, or (stops instead) the
    // joints on a stop that a step would push past it (held: an active set, refilled each step).
    struct Stillness
    {
      const std::vector<Eigen::Index> * pinned = nullptr;
      const JointStops * stops = nullptr;
      std::vector<Eigen::Index> * held = nullptr;
    };

    // Along -dq from q, a full step halved while it does not lower the loops' error (far from
    // the manifold the linearisation overshoots); q and size move to the first step that does.
    // Returns whether one did.
    bool searchLine(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const LoopConstraints & loops,
      const Stillness & still,
      Eigen::VectorXd & q,
      double & size,
      GaussNewtonWork & w)
    {
      for (double step = 1.; step > 1e-3; step *= 0.5)
      {
        pinocchio::integrate(model, q, (-step * w.dq).eval(), w.q_next);
        keepPinned(model, q, still.pinned, w.q_next);
        if (still.stops != nullptr) // the held joints where they were, all within their stops
        {
          keepPinned(model, q, still.held, w.q_next);
          clampToStops(*still.stops, w.q_next);
        }
        evaluateLoops(model, data, loops, w.q_next, w.error_next, nullptr, w.work_a, w.work_b);
        const double next = w.error_next.lpNorm<Eigen::Infinity>();
        if (next < size)
        {
          q.swap(w.q_next);
          size = next;
          return true;
        }
      }
      return false;
    }

    // Gauss-Newton onto the loops; on return w.error and w.J are those of the final q and w.svd
    // is J's decomposition (pinned columns, or with stops the columns of the joints on a stop,
    // zeroed). Returns the largest error left.
    // With stops, a joint on a stop stays there unless the step pulls it into its range: each
    // step is solved with the columns of the joints it would push past their stop zeroed (an
    // active set grown until it pushes none), and cut back onto the stops.
    double gaussNewton(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const LoopConstraints & loops,
      Eigen::VectorXd & q,
      double tolerance,
      int max_iterations,
      GaussNewtonWork & w,
      const Stillness & still = Stillness())
    {
      // A pinned joint's column is left out: the least-norm steps never move it.
      const auto evaluate = [&](bool all_on_stops) {
        evaluateLoops(model, data, loops, q, w.error, &w.J, w.work_a, w.work_b);
        if (still.pinned != nullptr)
          for (const Eigen::Index i : *still.pinned)
            w.J.col(i).setZero();
        if (all_on_stops)
        {
          findJointsOnStops(*still.stops, q, *still.held);
          for (const Eigen::Index i : *still.held)
            w.J.col(i).setZero();
        }
        w.svd.compute(w.J, Eigen::ComputeFullU | Eigen::ComputeFullV);
      };
      evaluate(false);
      double size = w.error.lpNorm<Eigen::Infinity>();
      for (int it = 0; it < max_iterations && size > tolerance; ++it)
      {
        solveLeastNorm(w.svd, svdRank(w.svd), w.error, w.dq);
        if (still.stops != nullptr)
        {
          still.held->clear();
          while (holdPushed(*still.stops, q, w.dq, *still.held, w.J))
          {
            w.svd.compute(w.J, Eigen::ComputeFullU | Eigen::ComputeFullV);
            solveLeastNorm(w.svd, svdRank(w.svd), w.error, w.dq);
          }
        }
        const bool improved = searchLine(model, data, loops, still, q, size, w);
        evaluate(false);
        if (!improved)
          break;
      }
      if (still.stops != nullptr)
        evaluate(true);
      return size;
    }
  } // namespace

  Eigen::VectorXd computeLoopError(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q)
  {
    Eigen::VectorXd error(loops.rows());
    pinocchio::Data::Matrix6x work_a(6, model.nv), work_b(6, model.nv);
    evaluateLoops(model, data, loops, q, error, nullptr, work_a, work_b);
    return error;
  }

  Eigen::MatrixXd computeLoopJacobian(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q)
  {
    Eigen::VectorXd error(loops.rows());
    Eigen::MatrixXd J(loops.rows(), model.nv);
    pinocchio::Data::Matrix6x work_a(6, model.nv), work_b(6, model.nv);
    evaluateLoops(model, data, loops, q, error, &J, work_a, work_b);
    return J;
  }

  LoopMotion computeLoopMotion(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q)
  {
    Eigen::VectorXd error(loops.rows());
    Eigen::MatrixXd J(loops.rows(), model.nv);
    pinocchio::Data::Matrix6x work_a(6, model.nv), work_b(6, model.nv);
    evaluateLoops(model, data, loops, q, error, &J, work_a, work_b);
    LoopMotion motion;
    motion.error = loops.empty() ? 0. : error.lpNorm<Eigen::Infinity>();
    if (loops.empty())
    {
      motion.basis = Eigen::MatrixXd::Identity(model.nv, model.nv);
      return motion;
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullV);
    motion.rank = static_cast<int>(svdRank(svd));
    motion.basis = svd.matrixV().rightCols(model.nv - motion.rank);
    return motion;
  }

  double projectOntoLoops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    Eigen::VectorXd & q,
    double tolerance,
    int max_iterations,
    const std::vector<Eigen::Index> * pinned)
  {
    if (loops.empty())
      return 0.;
    GaussNewtonWork work(model, loops);
    Stillness still;
    still.pinned = pinned;
    return gaussNewton(model, data, loops, q, tolerance, max_iterations, work, still);
  }

  namespace
  {
    // Why the loops cannot be assembled: the loop or coupling left most open at q (error) and
    // how open it was at the start (error_start).
    std::string describeOpenLoop(
      const pinocchio::Model & model,
      const LoopConstraints & loops,
      const Eigen::VectorXd & error,
      const Eigen::VectorXd & error_start)
    {
      Eigen::Index row = 0;
      std::size_t worst = 0;
      double worst_size = -1., worst_start = 0.;
      for (std::size_t k = 0; k < loops.loops().size(); ++k)
      {
        const int rows = loops.loops()[k].rows();
        const double size = error.segment(row, rows).lpNorm<Eigen::Infinity>();
        if (size > worst_size)
        {
          worst = k;
          worst_size = size;
          worst_start = error_start.segment(row, rows).lpNorm<Eigen::Infinity>();
        }
        row += rows;
      }
      const JointCoupling * coupling = nullptr;
      for (const JointCoupling & c : loops.couplings())
      {
        if (std::abs(error[row]) > worst_size)
        {
          coupling = &c;
          worst_size = std::abs(error[row]);
          worst_start = std::abs(error_start[row]);
        }
        ++row;
      }
      std::ostringstream msg;
      msg.precision(4);
      if (coupling != nullptr)
      {
        msg << "cannot assemble the couplings from the start configuration: " << coupling->name
            << " (q['" << model.names[coupling->follower] << "'] = " << coupling->multiplier
            << " * q['" << model.names[coupling->leader] << "'] + " << coupling->offset
            << ") is still off by " << worst_size << " (rad or m) after Gauss-Newton from "
            << worst_start;
        return msg.str();
      }
      const Loop & loop = loops.loops()[worst];
      msg << "cannot assemble the loops from the start configuration: " << loop.name << " ("
          << toString(loop.kind) << ", joint '" << model.names[loop.joint_a] << "' to joint '"
          << model.names[loop.joint_b] << "') is still " << worst_size
          << (loop.kind == LoopKind::Point ? " m" : " (m or rad)")
          << " apart after Gauss-Newton from " << worst_start
          << " (the links cannot reach each other from there, or the start is too far from an "
             "assembled pose; give [start] values close to one)";
      return msg.str();
    }
  } // namespace

  double assembleLoops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    Eigen::VectorXd & q)
  {
    if (loops.empty())
      return 0.;
    const Eigen::VectorXd start = q;
    const Eigen::VectorXd error_start = computeLoopError(model, data, loops, q);
    const double left = projectOntoLoops(model, data, loops, q, 1e-13, 100);
    if (!(left <= LoopStepper::kLoopTolerance))
    {
      // Name the loop that stays open.
      const Eigen::VectorXd error = computeLoopError(model, data, loops, q);
      q = start;
      throw std::invalid_argument(describeOpenLoop(model, loops, error, error_start));
    }
    return pinocchio::difference(model, start, q).lpNorm<Eigen::Infinity>();
  }

  // The stiffness of the closed mechanism along the motions N (orthonormal, allowed by the
  // loops), with the loop reactions lambda.
  StabilityReport assessOnMotions(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const Eigen::VectorXd & lambda,
    const Eigen::MatrixXd & N);

  namespace
  {
    // The static force's component along the allowed motions (N N^T tau), and the
    // least-squares reactions (J^T lambda = tau) when asked.
    Eigen::VectorXd projectedForce(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const LoopConstraints & loops,
      const Eigen::VectorXd & q,
      const ForceModel * forces,
      Eigen::VectorXd * lambda)
    {
      const Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
      if (loops.empty())
        return tau;
      const Eigen::MatrixXd J = computeLoopJacobian(model, data, loops, q);
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullU | Eigen::ComputeFullV);
      const Eigen::Index rank = svdRank(svd);
      const Eigen::MatrixXd N = svd.matrixV().rightCols(model.nv - rank);
      if (lambda != nullptr) // J^T lambda = tau: lambda = U_r S_r^-1 V_r^T tau
        *lambda = svd.matrixU().leftCols(rank)
                  * (svd.matrixV().leftCols(rank).transpose() * tau)
                      .cwiseQuotient(svd.singularValues().head(rank));
      return N * (N.transpose() * tau);
    }
  } // namespace

  Eigen::VectorXd computeStaticForce(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    return projectedForce(model, data, loops, q, forces, nullptr);
  }

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    if (loops.empty())
      return assessStability(model, data, q, forces);
    Eigen::VectorXd lambda;
    projectedForce(model, data, loops, q, forces, &lambda);
    const Eigen::MatrixXd N = computeLoopMotion(model, data, loops, q).basis;
    return assessOnMotions(model, data, loops, q, forces, lambda, N);
  }

  StabilityReport assessOnMotions(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const Eigen::VectorXd & lambda,
    const Eigen::MatrixXd & N)
  {
    const Eigen::MatrixXd K = computeStiffnessMatrix(model, data, q, forces);
    // The reactions' stiffness d(J^T lambda)/dq along the allowed motions, lambda held.
    const double h = 1e-6;
    Eigen::MatrixXd C(model.nv, N.cols());
    Eigen::VectorXd q_plus(model.nq), q_minus(model.nq);
    for (Eigen::Index k = 0; k < N.cols(); ++k)
    {
      pinocchio::integrate(model, q, (h * N.col(k)).eval(), q_plus);
      pinocchio::integrate(model, q, (-h * N.col(k)).eval(), q_minus);
      C.col(k) = (computeLoopJacobian(model, data, loops, q_plus).transpose() * lambda
                  - computeLoopJacobian(model, data, loops, q_minus).transpose() * lambda)
                 / (2. * h);
    }
    const Eigen::MatrixXd reduced = N.transpose() * (K * N - C);
    StabilityReport report = assessStiffness(reduced, 1e-7, computeStiffnessFloor(model, true));
    report.softest_direction = N * report.softest_direction;
    report.basis = N;
    return report;
  }

  namespace
  {
    // A joint on a stop in balanceStops: its stop, the side, and whether its reaction is solved
    // for (a stop that would pull is let go).
    struct OnStop
    {
      const JointStops::Stop * stop;
      StopSide side;
      bool active;
    };

    std::vector<OnStop> stopsToBalance(const JointStops & stops, const Eigen::VectorXd & q)
    {
      std::vector<OnStop> on;
      for (const StopReached & r : findStopsReached(stops, q))
        on.push_back(OnStop{r.stop, r.side, true});
      return on;
    }

    // The active stops' reactions mu (one per entry of on, 0 for those let go) that balance
    // tau best along the allowed motions N, and what they leave unbalanced.
    void solveStopReactions(
      const Eigen::MatrixXd & N,
      const std::vector<OnStop> & on,
      const Eigen::VectorXd & tau,
      Eigen::VectorXd & mu,
      Eigen::VectorXd & unbalanced)
    {
      std::vector<std::size_t> active;
      for (std::size_t k = 0; k < on.size(); ++k)
        if (on[k].active)
          active.push_back(k);
      Eigen::MatrixXd B(N.rows(), static_cast<Eigen::Index>(active.size()));
      for (std::size_t c = 0; c < active.size(); ++c)
        B.col(static_cast<Eigen::Index>(c)) =
          N * N.row(on[active[c]].stop->iv).transpose(); // P e_i
      mu = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(on.size()));
      if (active.empty())
        return;
      const Eigen::VectorXd x = B.completeOrthogonalDecomposition().solve(tau);
      for (std::size_t c = 0; c < active.size(); ++c)
        mu[static_cast<Eigen::Index>(active[c])] = x[static_cast<Eigen::Index>(c)];
      unbalanced = tau - B * x;
    }

    // The active stop whose reaction pulls hardest, or on.size() when none pulls.
    std::size_t findHardestPull(const std::vector<OnStop> & on, const Eigen::VectorXd & mu)
    {
      std::size_t worst = on.size();
      double worst_pull = 0.;
      for (std::size_t k = 0; k < on.size(); ++k)
      {
        if (!on[k].active)
          continue;
        const double sign = on[k].side == StopSide::Lower ? 1. : -1.;
        const double pull = -sign * mu[static_cast<Eigen::Index>(k)];
        if (pull > worst_pull)
        {
          worst_pull = pull;
          worst = k;
        }
      }
      return worst;
    }
  } // namespace

  StopBalance balanceStops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau)
  {
    // Joints on a stop: their reactions mu (side * mu >= 0) enter as P E^T mu, P the projector
    // onto the allowed motions; a stop that would pull is let go and the others solved again.
    std::vector<OnStop> on = stopsToBalance(stops, q);
    StopBalance balance;
    balance.unbalanced = tau;
    Eigen::VectorXd mu;
    if (!on.empty())
    {
      const Eigen::MatrixXd N = computeLoopMotion(model, data, loops, q).basis;
      for (std::size_t pass = 0; pass <= on.size(); ++pass)
      {
        solveStopReactions(N, on, tau, mu, balance.unbalanced);
        const std::size_t worst = findHardestPull(on, mu); // let go of it, if any
        if (worst == on.size())
          break;
        on[worst].active = false;
      }
    }
    for (std::size_t k = 0; k < on.size(); ++k)
    {
      const double sign = on[k].side == StopSide::Lower ? 1. : -1.;
      balance.contacts.push_back(
        StopContact{
          on[k].stop->joint, on[k].side,
          on[k].active ? std::max(0., sign * mu[static_cast<Eigen::Index>(k)]) : 0.});
    }
    balance.residual = balance.unbalanced.lpNorm<Eigen::Infinity>();
    return balance;
  }

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    // The loop reactions lambda of the rest: J^T lambda = tau - E^T mu, the stops' reactions
    // mu taken out first.
    const Eigen::VectorXd tau_net = computeStaticForce(model, data, loops, q, forces);
    const StopBalance balance = balanceStops(model, data, loops, stops, q, tau_net);
    Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
    const double tolerance = 1e-9 * std::max(tau.lpNorm<Eigen::Infinity>(), 1e-300);
    std::vector<Eigen::Index> held;
    for (const StopContact & c : balance.contacts)
      if (c.reaction > tolerance)
      {
        const Eigen::Index iv = model.idx_vs[c.joint];
        held.push_back(iv);
        tau[iv] -= c.side == StopSide::Lower ? c.reaction : -c.reaction;
      }
    const Eigen::MatrixXd J = computeLoopJacobian(model, data, loops, q);
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Index rank = svdRank(svd);
    const Eigen::VectorXd lambda = svd.matrixU().leftCols(rank)
                                   * (svd.matrixV().leftCols(rank).transpose() * tau)
                                       .cwiseQuotient(svd.singularValues().head(rank));
    // The motions the loops allow that keep the held joints still: N times the null space of
    // the held rows of N.
    const Eigen::MatrixXd N = svd.matrixV().rightCols(model.nv - rank);
    Eigen::MatrixXd motions = N;
    if (!held.empty())
    {
      Eigen::MatrixXd rows(static_cast<Eigen::Index>(held.size()), N.cols());
      for (std::size_t k = 0; k < held.size(); ++k)
        rows.row(static_cast<Eigen::Index>(k)) = N.row(held[k]);
      Eigen::JacobiSVD<Eigen::MatrixXd> held_svd(rows, Eigen::ComputeFullV);
      const Eigen::Index held_rank = svdRank(held_svd);
      motions = N * held_svd.matrixV().rightCols(N.cols() - held_rank);
    }
    if (motions.cols() == 0)
    {
      // Every motion is held: the rest is stable, as for a tree whose joints all rest on stops.
      StabilityReport report;
      report.verdict = Stability::Stable;
      report.basis = motions;
      report.stiffness.resize(0, 0);
      report.softest_direction = Eigen::VectorXd::Zero(model.nv);
      return report;
    }
    return assessOnMotions(model, data, loops, q, forces, lambda, motions);
  }

  TimeScale computeTimeScale(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    if (loops.empty())
      return computeTimeScale(model, data, q, forces, false);
    const StabilityReport report = assessStability(model, data, loops, q, forces);
    const Eigen::MatrixXd & N = report.basis;
    const Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
    const bool damped = forces != nullptr && forces->hasDamping();
    Eigen::MatrixXd D;
    if (damped)
      D = N.transpose() * computeDampingMatrix(model, data, q, forces) * N;
    prebuilt::crba(model, data, q);
    const Eigen::MatrixXd M =
      N.transpose() * Eigen::MatrixXd(data.M.selfadjointView<Eigen::Upper>()) * N;
    return computeTimeScale(
      report.stiffness, M, Eigen::VectorXd(N.transpose() * tau), damped ? &D : nullptr, false);
  }

  // --- the solver's per-step work ----------------------------------------------------------

  struct LoopStepper::Impl : GaussNewtonWork
  {
    typedef pinocchio::RigidConstraintModel ConstraintModel;
    typedef pinocchio::RigidConstraintData ConstraintData;

    Impl(const pinocchio::Model & model, const LoopConstraints & loops)
    : GaussNewtonWork(model, loops)
    , model(model)
    , loops(loops)
    , tau(model.nv)
    , zero(Eigen::VectorXd::Zero(model.nv))
    {
      if (!loops.couplings().empty())
      {
        // constraintDynamics takes frame constraints only; a coupling of joints is none. The
        // couplings' Jacobian is constant: the motions they allow, an orthonormal basis N, are
        // found once, and the dynamics are those of the reduced coordinates s (v = N s), with
        // the loops' rows, if any, as constraints on s.
        Eigen::MatrixXd Jc = Eigen::MatrixXd::Zero(loops.rows(), model.nv);
        Eigen::Index row = 0;
        for (const JointCoupling & c : loops.couplings())
        {
          Jc(row, c.iv_follower) = 1.;
          Jc(row, c.iv_leader) -= c.multiplier;
          ++row;
        }
        Eigen::JacobiSVD<Eigen::MatrixXd> jsvd(Jc, Eigen::ComputeFullV);
        N = jsvd.matrixV().rightCols(model.nv - svdRank(jsvd));
        reduced_mass.resize(N.cols(), N.cols());
        reduced_force.resize(N.cols());
        MN.resize(model.nv, N.cols());
        gamma.resize(loops.rows());
        // Sized by a factorization (assigning LLT(n) copies an unset info()).
        mass_llt.compute(Eigen::MatrixXd::Identity(N.cols(), N.cols()));
        return;
      }
      for (const Loop & loop : loops.loops())
      {
        // LOCAL_WORLD_ALIGNED: the same axes as the errors and Jacobians above.
        constraint_models.push_back(ConstraintModel(
          loop.kind == LoopKind::Point ? pinocchio::CONTACT_3D : pinocchio::CONTACT_6D, model,
          loop.joint_a, loop.placement_a, loop.joint_b, loop.placement_b,
          pinocchio::LOCAL_WORLD_ALIGNED));
        constraint_models.back().name = loop.name;
      }
      for (const ConstraintModel & cm : constraint_models)
        constraint_datas.push_back(ConstraintData(cm));
    }

    const pinocchio::Model & model;
    const LoopConstraints & loops;
    prebuilt::ConstraintModelVector constraint_models;
    prebuilt::ConstraintDataVector constraint_datas;
    pinocchio::ProximalSettings prox;
    Eigen::VectorXd tau, zero, velocity;
    // Couplings only: the allowed motions N and the reduced dynamics' workspace.
    Eigen::MatrixXd N, MN, reduced_mass;
    Eigen::VectorXd reduced_force, gamma;
    Eigen::LLT<Eigen::MatrixXd> mass_llt;
    // Impacts: the arriving velocity, the rows held (loops and pinned joints), M^-1 A^T.
    Eigen::VectorXd arriving, impulse;
    Eigen::MatrixXd mass, A, MinvAt, delassus;
    Eigen::LLT<Eigen::MatrixXd> full_mass_llt;
    // The stops, if any; the joints a projection with stops held on theirs.
    const JointStops * stops = nullptr;
    std::vector<Eigen::Index> held;
  };

  LoopStepper::LoopStepper(const pinocchio::Model & model, const LoopConstraints & loops)
  : impl_(new Impl(model, loops))
  {
  }

  LoopStepper::~LoopStepper() = default;

  void LoopStepper::init(pinocchio::Data & data, const Eigen::VectorXd & q)
  {
    Impl & d = *impl_;
    if (d.constraint_models.empty()) // couplings only: no constraint data to set up
      return;
    prebuilt::initConstraintDynamics(d.model, data, d.constraint_models, d.constraint_datas);
    // Redundant equations make the Delassus matrix J M^-1 J^T singular; the proximal iterations
    // of constraintDynamics handle that with a regularisation mu, here 1e-12 of the matrix's
    // scale (its largest diagonal entry), so that one or two iterations converge.
    const Eigen::MatrixXd Jq = computeLoopJacobian(d.model, data, d.loops, q);
    // M^-1 through the instantiations pinocchio_default carries (aba, then computeMinverse
    // from its articulated inertias): computeMinverse(model, data, q) compiles here again.
    prebuilt::aba(d.model, data, q, d.zero, d.zero, pinocchio::Convention::WORLD);
    pinocchio::computeMinverse(d.model, data);
    const Eigen::MatrixXd Minv = data.Minv.selfadjointView<Eigen::Upper>();
    const double scale = (Jq * Minv * Jq.transpose()).diagonal().maxCoeff();
    d.prox = pinocchio::ProximalSettings(1e-14, std::max(1e-12 * scale, 1e-300), 20);
  }

  void LoopStepper::dynamics(
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    const Eigen::VectorXd & tau,
    const ForceVector * fext)
  {
    Impl & d = *impl_;
    const pinocchio::Model & model = d.model;
    d.tau = tau;
    if (d.constraint_models.empty())
    {
      // Couplings only (a constant Jacobian, no drift): M a = tau - b + J^T lambda with J a = 0
      // is a = N (N^T M N)^-1 N^T (tau - b). rnea leaves the body velocities in data.v.
      prebuilt::crba(model, data, q);
      if (fext != nullptr)
        d.tau -= pinocchio::rnea(model, data, q, v, d.zero, *fext);
      else
        d.tau -= pinocchio::rnea(model, data, q, v, d.zero);
      d.MN.noalias() = data.M.selfadjointView<Eigen::Upper>() * d.N;
      d.reduced_mass.noalias() = d.N.transpose() * d.MN;
      d.reduced_force.noalias() = d.N.transpose() * d.tau;
      d.mass_llt.compute(d.reduced_mass);
      d.mass_llt.solveInPlace(d.reduced_force);
      if (!d.loops.loops().empty())
        loopAcceleration(data, q, v);
      data.ddq.noalias() = d.N * d.reduced_force;
      return;
    }
    if (fext != nullptr) // constraintDynamics takes no fext: add their joint efforts
    {
      d.tau += pinocchio::computeGeneralizedGravity(model, data, q);
      d.tau -= pinocchio::rnea(model, data, q, d.zero, d.zero, *fext);
    }
    prebuilt::constraintDynamics(
      model, data, q, v, d.tau, d.constraint_models, d.constraint_datas, d.prox);
    // Body velocities in their own frames, as aba leaves them for the energy measures.
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
      data.v[i] = data.oMi[i].actInv(data.ov[i]);
  }

  void LoopStepper::loopAcceleration(
    pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    // Loops with couplings: the loops' rows J N s_dot = -gamma, gamma = Jdot v (the relative
    // acceleration of their ends at zero joint acceleration), the reactions lambda by least
    // squares (redundant rows): s_dot = s_free + M_r^-1 (J N)^T lambda.
    Impl & d = *impl_;
    const pinocchio::Model & model = d.model;
    evaluateLoops(model, data, d.loops, q, d.error, &d.J, d.work_a, d.work_b);
    pinocchio::forwardKinematics(model, data, q, v, d.zero); // data.a: the bias accelerations
    Eigen::Index rows = 0;
    for (const Loop & loop : d.loops.loops())
    {
      Eigen::Vector3d linear = Eigen::Vector3d::Zero(), angular = Eigen::Vector3d::Zero();
      for (const double sign : {1., -1.})
      {
        const pinocchio::JointIndex joint = sign > 0. ? loop.joint_a : loop.joint_b;
        const pinocchio::SE3 & placement = sign > 0. ? loop.placement_a : loop.placement_b;
        if (joint == 0)
          continue;
        const pinocchio::Motion velocity = placement.actInv(data.v[joint]);
        const pinocchio::Motion acceleration = placement.actInv(data.a[joint]);
        const Eigen::Matrix3d R = data.oMi[joint].rotation() * placement.rotation();
        linear += sign * R * (acceleration.linear() + velocity.angular().cross(velocity.linear()));
        angular += sign * R * acceleration.angular();
      }
      d.gamma.segment<3>(rows) = linear;
      if (loop.kind == LoopKind::Frame)
        d.gamma.segment<3>(rows + 3) = angular;
      rows += loop.rows();
    }
    const Eigen::MatrixXd JN = d.J.topRows(rows) * d.N;
    const Eigen::MatrixXd MinvJt = d.mass_llt.solve(JN.transpose());
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(
      JN * MinvJt, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::VectorXd lambda;
    solveLeastNorm(svd, svdRank(svd), (-d.gamma.head(rows) - JN * d.reduced_force).eval(), lambda);
    d.reduced_force.noalias() += MinvJt * lambda;
  }

  double LoopStepper::project(
    pinocchio::Data & data,
    Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    const std::vector<Eigen::Index> * pinned)
  {
    Impl & d = *impl_;
    const ClosedLoops closed = closeLoops(data, q, pinned);
    // v <- v - J^+ J v: the nearest velocity the loops allow.
    const Eigen::Index rank = svdRank(d.svd);
    d.error_next.noalias() = d.J * v;
    solveLeastNorm(d.svd, rank, d.error_next, d.dq);
    if (closed.still != nullptr) // exactly unchanged (keepPinned)
      for (const Eigen::Index i : *closed.still)
        d.dq[i] = 0.;
    v -= d.dq;
    return closed.left;
  }

  void LoopStepper::useStops(const JointStops * stops)
  {
    impl_->stops = stops;
  }

  LoopStepper::ClosedLoops LoopStepper::closeLoops(
    pinocchio::Data & data, Eigen::VectorXd & q, const std::vector<Eigen::Index> * pinned)
  {
    Impl & d = *impl_;
    Stillness still;
    still.pinned = pinned;
    ClosedLoops closed{gaussNewton(d.model, data, d.loops, q, 1e-13, 10, d, still), pinned};
    // The joints on a stop hold the loops open: those the loops pull off their stop leave it.
    if (closed.left > kLoopTolerance && pinned != nullptr && d.stops != nullptr)
    {
      Stillness on_stops;
      on_stops.stops = d.stops;
      on_stops.held = &d.held;
      closed.left = gaussNewton(d.model, data, d.loops, q, 1e-13, 50, d, on_stops);
      closed.still = &d.held;
    }
    return closed;
  }

  void LoopStepper::arrive(const Eigen::VectorXd & v)
  {
    impl_->arriving = v;
  }

  double LoopStepper::impact(
    pinocchio::Data & data,
    Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    const std::vector<Eigen::Index> & pinned)
  {
    Impl & d = *impl_;
    const pinocchio::Model & model = d.model;
    const ClosedLoops closed = closeLoops(data, q, &pinned);
    const std::vector<Eigen::Index> & still = *closed.still;
    // The rows held: the loops' (pinned columns zeroed, which the pinned rows make equivalent)
    // and one per pinned joint. v = v_a - M^-1 A^T mu with (A M^-1 A^T) mu = A v_a, least norm
    // (the rows are often redundant: a weld over a chain with a joint on its stop).
    const Eigen::Index m = d.J.rows(), p = static_cast<Eigen::Index>(still.size());
    d.A.setZero(m + p, model.nv);
    d.A.topRows(m) = d.J;
    for (Eigen::Index k = 0; k < p; ++k)
      d.A(m + k, still[static_cast<std::size_t>(k)]) = 1.;
    prebuilt::crba(model, data, q);
    d.mass = data.M.selfadjointView<Eigen::Upper>();
    d.full_mass_llt.compute(d.mass);
    d.MinvAt = d.full_mass_llt.solve(d.A.transpose());
    d.delassus.noalias() = d.A * d.MinvAt;
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(
      d.delassus.rows(), d.delassus.cols());
    // Relative to the largest pivot: round-off pivots of redundant rows are rank, not force.
    cod.setThreshold(1e-10);
    cod.compute(d.delassus);
    d.impulse = cod.solve((d.A * d.arriving).eval());
    v = d.arriving;
    v.noalias() -= d.MinvAt * d.impulse;
    for (const Eigen::Index i : still)
      v[i] = 0.;
    return closed.left;
  }

} // namespace pinsettle
