//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/elements.hpp"
#include "joint-kinds.hpp"

#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace pinsettle
{

  namespace
  {
    void checkCoefficient(double value, const char * name, const char * element)
    {
      if (!(std::isfinite(value) && value >= 0.))
      {
        std::ostringstream msg;
        msg << element << ": " << name << " must be finite and >= 0, got " << value;
        throw std::invalid_argument(msg.str());
      }
    }

    void checkFinite(const Eigen::VectorXd & x, const char * name, const char * element)
    {
      if (!x.allFinite())
      {
        std::ostringstream msg;
        msg << element << ": every entry of " << name << " must be finite, got [" << x.transpose()
            << "]";
        throw std::invalid_argument(msg.str());
      }
    }

    // World position of a point and, when wanted, its world velocity, from the kinematics of a
    // forwardKinematics pass (data.oMi, and data.v in local frames when with_velocity).
    Eigen::Vector3d worldPoint(const pinocchio::Data & data, const Attachment & at)
    {
      return data.oMi[at.joint].act(at.point);
    }

    Eigen::Vector3d worldPointVelocity(const pinocchio::Data & data, const Attachment & at)
    {
      if (at.joint == 0)
        return Eigen::Vector3d::Zero();
      const pinocchio::Motion & vi = data.v[at.joint];
      return data.oMi[at.joint].rotation() * (vi.linear() + vi.angular().cross(at.point));
    }

    // A joint spring's stretch q - rest (rad or m); for a continuous joint, (cos, sin), the
    // angle less rest wrapped to [-pi, pi].
    double jointStretch(
      const pinocchio::Model & model, const JointSpring & s, const Eigen::VectorXd & q)
    {
      const int iq = model.idx_qs[s.joint];
      if (model.nqs[s.joint] == 2)
        return std::remainder(std::atan2(q[iq + 1], q[iq]) - s.rest, 2. * M_PI);
      return q[iq] - s.rest;
    }

    // A point spring's span at the kinematics in data: its ends (world), its length, the unit
    // vector u from a to b and the elastic tension k (|d| - rest_length) along it. At coincident
    // ends the direction is undefined: u is zero, and so is the spring's force (a zero-length
    // spring pulls with k d = 0 there anyway).
    struct Span
    {
      Eigen::Vector3d a, b, u;
      double length, tension;
    };

    Span springSpan(const pinocchio::Data & data, const PointSpring & s)
    {
      Span span;
      span.a = worldPoint(data, s.a);
      span.b = worldPoint(data, s.b);
      const Eigen::Vector3d d = span.b - span.a;
      span.length = d.norm();
      span.u = span.length > 0. ? Eigen::Vector3d(d / span.length) : Eigen::Vector3d::Zero();
      span.tension = span.length > 0. ? s.stiffness * (span.length - s.rest_length) : 0.;
      return span;
    }

    // A world-aligned force (N) and torque (N m) at a point, as the spatial force on the joint,
    // in the joint's frame (the convention of the fext argument of aba and rnea).
    void addWorldForce(
      const pinocchio::Data & data,
      const Attachment & at,
      const Eigen::Vector3d & force,
      const Eigen::Vector3d & torque,
      ForceVector & fext)
    {
      if (at.joint == 0)
        return; // the world takes any force
      const Eigen::Matrix3d & R = data.oMi[at.joint].rotation();
      const Eigen::Vector3d f = R.transpose() * force;
      fext[at.joint].linear() += f;
      fext[at.joint].angular() += R.transpose() * torque + at.point.cross(f);
    }

    // Whether every joint from the root to `joint` moves by the exponential of its tangent
    // directions, which the closed-form stiffness relies on (hasVaryingMotionSubspace).
    bool hasClosedFormSupport(const pinocchio::Model & model, pinocchio::JointIndex joint)
    {
      for (pinocchio::JointIndex j = joint; j > 0; j = model.parents[j])
        if (hasVaryingMotionSubspace(model.joints[j]))
          return false;
      return true;
    }

    // The world point Jacobian of a point p (world) of body `joint`, added to G (3 x nv) with
    // a sign: the velocity v_m + w_m x p of each column of the world Jacobian data.J on the
    // support (computeJointJacobians).
    void addPointJacobian(
      const pinocchio::Model & model,
      const pinocchio::Data & data,
      pinocchio::JointIndex joint,
      const Eigen::Vector3d & p,
      double sign,
      Eigen::Matrix3Xd & G)
    {
      for (pinocchio::JointIndex j = joint; j > 0; j = model.parents[j])
        for (int m = model.idx_vs[j]; m < model.idx_vs[j] + model.nvs[j]; ++m)
        {
          const auto column = data.J.col(m);
          G.col(m) += sign * (column.head<3>() + column.tail<3>().cross(p));
        }
    }

    // -d(J_p^T F)/dq for a force f and torque t held fixed in the world at the point p (world)
    // of body `joint`: the wrench at the world origin is F = (f, t + p x f). A step along m
    // turns the columns J_k below it, dJ_k = J_m x J_k (hasClosedFormSupport), and moves the
    // point by J_m's velocity at p, which turns the moment p x f.
    void addFixedWrenchStiffness(
      const pinocchio::Model & model,
      const pinocchio::Data & data,
      pinocchio::JointIndex joint,
      const Eigen::Vector3d & p,
      const Eigen::Vector3d & f,
      const Eigen::Vector3d & t,
      Eigen::MatrixXd & K)
    {
      const pinocchio::Force F(f, t + p.cross(f));
      for (pinocchio::JointIndex jk = joint; jk > 0; jk = model.parents[jk])
        for (int k = model.idx_vs[jk]; k < model.idx_vs[jk] + model.nvs[jk]; ++k)
        {
          const pinocchio::Motion Jk(data.J.col(k));
          for (pinocchio::JointIndex jm = joint; jm > 0; jm = model.parents[jm])
            for (int m = model.idx_vs[jm]; m < model.idx_vs[jm] + model.nvs[jm]; ++m)
            {
              const pinocchio::Motion Jm(data.J.col(m));
              const Eigen::Vector3d dp = Jm.linear() + Jm.angular().cross(p);
              double d = Jk.angular().dot(dp.cross(f));
              if (jm <= jk) // on one path from the root: jm is jk or an ancestor of it
                d += Jm.cross(Jk).dot(F);
              K(k, m) -= d;
            }
        }
    }
  } // namespace

  ForceElements::ForceElements(const pinocchio::Model & model)
  : model_(model)
  , joint_loads_(Eigen::VectorXd::Zero(model.nv))
  {
  }

  Attachment ForceElements::attach(
    pinocchio::FrameIndex frame, const Eigen::Vector3d & point, const char * what) const
  {
    if (frame >= model_.frames.size())
    {
      std::ostringstream msg;
      msg << what << ": frame index " << frame << " is out of range (the model has "
          << model_.frames.size() << " frames)";
      throw std::invalid_argument(msg.str());
    }
    checkFinite(point, "point", what);
    const pinocchio::Frame & f = model_.frames[frame];
    // Frames of a fixed link (or of a joint removed by buildReducedModel) sit on their parent
    // joint at a fixed placement.
    return Attachment{f.parentJoint, f.placement.act(point)};
  }

  void ForceElements::addJointSpring(
    pinocchio::JointIndex joint, double stiffness, double rest, double damping)
  {
    const char * what = "joint spring";
    if (joint == 0 || joint >= static_cast<pinocchio::JointIndex>(model_.njoints))
    {
      std::ostringstream msg;
      msg << what << ": joint index " << joint << " is not a joint of the model (1 to "
          << model_.njoints - 1 << ")";
      throw std::invalid_argument(msg.str());
    }
    if (model_.nvs[joint] != 1)
    {
      std::ostringstream msg;
      msg << what << ": joint '" << model_.names[joint] << "' is a "
          << model_.joints[joint].shortname() << " with " << model_.nvs[joint]
          << " degrees of freedom; a joint spring needs a 1-DoF joint (revolute, continuous, "
             "prismatic)";
      throw std::invalid_argument(msg.str());
    }
    checkCoefficient(stiffness, "stiffness", what);
    checkCoefficient(damping, "damping", what);
    if (!std::isfinite(rest))
      throw std::invalid_argument("joint spring: rest must be finite");
    joint_springs_.push_back(JointSpring{joint, stiffness, rest, damping});
    joint_damping_ = joint_damping_ || damping > 0.;
  }

  void ForceElements::addPointSpring(
    pinocchio::FrameIndex frame_a,
    const Eigen::Vector3d & point_a,
    pinocchio::FrameIndex frame_b,
    const Eigen::Vector3d & point_b,
    double stiffness,
    double rest_length,
    double damping)
  {
    const char * what = "spring";
    const Attachment a = attach(frame_a, point_a, what), b = attach(frame_b, point_b, what);
    checkCoefficient(stiffness, "stiffness", what);
    checkCoefficient(rest_length, "rest_length", what);
    checkCoefficient(damping, "damping", what);
    if (a.joint == b.joint)
      throw std::invalid_argument(
        "spring: both ends are on the same rigid body (joint '" + model_.names[a.joint]
        + "'); such a spring exerts no net effort");
    point_springs_.push_back(PointSpring{a, b, stiffness, rest_length, damping});
    points_differenced_ = points_differenced_ || !hasClosedFormSupport(model_, a.joint)
                          || !hasClosedFormSupport(model_, b.joint);
    spring_damping_ = spring_damping_ || damping > 0.;
  }

  bool ForceElements::tiesToWorld(const pinocchio::Model & model, pinocchio::JointIndex root) const
  {
    for (const JointSpring & spring : joint_springs_)
      if (spring.joint == root)
        return true;
    if (has_joint_loads_ && !joint_loads_.segment(model.idx_vs[root], model.nvs[root]).isZero(0.))
      return true;
    for (const PointSpring & spring : point_springs_)
      if (isInSubtree(model, spring.a.joint, root) != isInSubtree(model, spring.b.joint, root))
        return true;
    return false;
  }

  void ForceElements::addJointLoad(pinocchio::JointIndex joint, const Eigen::VectorXd & effort)
  {
    const char * what = "joint load";
    if (joint == 0 || joint >= static_cast<pinocchio::JointIndex>(model_.njoints))
    {
      std::ostringstream msg;
      msg << what << ": joint index " << joint << " is not a joint of the model (1 to "
          << model_.njoints - 1 << ")";
      throw std::invalid_argument(msg.str());
    }
    if (effort.size() != model_.nvs[joint])
    {
      std::ostringstream msg;
      msg << what << ": joint '" << model_.names[joint] << "' has " << model_.nvs[joint]
          << " degrees of freedom, the effort has " << effort.size() << " entries";
      throw std::invalid_argument(msg.str());
    }
    checkFinite(effort, "effort", what);
    joint_loads_.segment(model_.idx_vs[joint], model_.nvs[joint]) += effort;
    has_joint_loads_ = true;
  }

  void ForceElements::addPointLoad(
    pinocchio::FrameIndex frame,
    const Eigen::Vector3d & point,
    const Eigen::Vector3d & force,
    const Eigen::Vector3d & torque)
  {
    const char * what = "load";
    const Attachment at = attach(frame, point, what);
    checkFinite(force, "force", what);
    checkFinite(torque, "torque", what);
    if (at.joint == 0)
      throw std::invalid_argument("load: the frame is fixed to the world; the load does nothing");
    point_loads_.push_back(PointLoad{at, force, torque});
    points_differenced_ = points_differenced_ || !hasClosedFormSupport(model_, at.joint);
  }

  void ForceElements::addStiffness(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    Eigen::MatrixXd & K) const
  {
    // -d(-k stretch)/dq = k: the stretch moves one for one with the joint's velocity coordinate
    // (a continuous joint's angle too); joint loads are constant.
    for (const JointSpring & s : joint_springs_)
    {
      const int iv = model.idx_vs[s.joint];
      K(iv, iv) += s.stiffness;
    }
    if (!hasExternalForces())
      return;
    pinocchio::computeJointJacobians(model, data, q);

    Eigen::Matrix3Xd G(3, model.nv);
    for (const PointSpring & s : point_springs_)
    {
      // The tension T u on a (u along d = b - a) changes with d by
      // K_c = k u u^T + T / |d| (I - u u^T), and d with q by G = J_b - J_a: G^T K_c G. At
      // coincident ends (no force) the stiffness is taken as k in every direction, exact for a
      // zero rest length.
      const Span span = springSpan(data, s);
      Eigen::Matrix3d Kc = s.stiffness * Eigen::Matrix3d::Identity();
      if (span.length > 0.)
        Kc = span.tension / span.length * Eigen::Matrix3d::Identity()
             + (s.stiffness - span.tension / span.length) * span.u * span.u.transpose();
      const Eigen::Vector3d force_on_a = span.tension * span.u;
      G.setZero();
      addPointJacobian(model, data, s.b.joint, span.b, 1., G);
      addPointJacobian(model, data, s.a.joint, span.a, -1., G);
      K.noalias() += G.transpose() * Kc * G;
      addFixedWrenchStiffness(
        model, data, s.a.joint, span.a, force_on_a, Eigen::Vector3d::Zero(), K);
      addFixedWrenchStiffness(
        model, data, s.b.joint, span.b, -force_on_a, Eigen::Vector3d::Zero(), K);
    }
    for (const PointLoad & l : point_loads_)
      addFixedWrenchStiffness(
        model, data, l.at.joint, worldPoint(data, l.at), l.force, l.torque, K);
  }

  double ForceElements::pointEnergy(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q) const
  {
    pinocchio::forwardKinematics(model, data, q);
    double energy = 0.;
    for (const PointSpring & s : point_springs_)
    {
      const Span span = springSpan(data, s);
      energy += 0.5 * s.stiffness * std::pow(span.length - s.rest_length, 2);
    }
    for (const PointLoad & l : point_loads_)
      energy -= l.force.dot(worldPoint(data, l.at));
    return energy;
  }

  double ForceElements::computeWork(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q_from,
    const Eigen::VectorXd & q_to,
    const Eigen::VectorXd & motion) const
  {
    for (const PointLoad & l : point_loads_)
      if (!l.torque.isZero(0.))
        return std::numeric_limits<double>::quiet_NaN();
    double work = 0.;
    if (has_joint_loads_)
      work += joint_loads_.dot(motion);
    for (const JointSpring & s : joint_springs_)
      work +=
        0.5 * s.stiffness
        * (std::pow(jointStretch(model, s, q_from), 2) - std::pow(jointStretch(model, s, q_to), 2));
    if (hasExternalForces())
      work += pointEnergy(model, data, q_from) - pointEnergy(model, data, q_to);
    return work;
  }

  void ForceElements::computeForces(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    Eigen::VectorXd & tau,
    ForceVector & fext) const
  {
    if (model.nv != model_.nv || model.njoints != model_.njoints)
      throw std::invalid_argument(
        "ForceElements: called with a model other than the one they were built for");

    if (has_joint_loads_)
      tau += joint_loads_;

    for (const JointSpring & s : joint_springs_)
    {
      const int iv = model.idx_vs[s.joint];
      tau[iv] -= s.stiffness * jointStretch(model, s, q) + s.damping * v[iv];
    }

    if (!hasExternalForces())
      return;
    if (spring_damping_)
      pinocchio::forwardKinematics(model, data, q, v);
    else
      pinocchio::forwardKinematics(model, data, q);

    const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
    for (const PointSpring & s : point_springs_)
    {
      const Span span = springSpan(data, s);
      double tension = span.tension;
      if (s.damping > 0.) // u is zero at coincident ends: no force
        tension +=
          s.damping * span.u.dot(worldPointVelocity(data, s.b) - worldPointVelocity(data, s.a));
      const Eigen::Vector3d force_on_a = tension * span.u;
      addWorldForce(data, s.a, force_on_a, zero, fext);
      addWorldForce(data, s.b, -force_on_a, zero, fext);
    }

    for (const PointLoad & l : point_loads_)
      addWorldForce(data, l.at, l.force, l.torque, fext);
  }

} // namespace pinsettle
