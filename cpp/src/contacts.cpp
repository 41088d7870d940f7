//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/contacts.hpp"
#include "pinsettle/prebuilt.hpp"
#include "pinsettle/statics.hpp"

#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace pinsettle
{

  namespace
  {
    void throwContactError(
      const std::string & what, const std::string & name, const std::string & msg)
    {
      throw std::invalid_argument(what + " '" + name + "': " + msg);
    }

    void checkFriction(const std::string & ground, double friction)
    {
      if (!(friction >= 0.) || !std::isfinite(friction))
        throwContactError(
          "ground", ground,
          "friction must be a finite coefficient >= 0, got " + std::to_string(friction));
    }

    // Two unit tangents completing the normal n to a right-handed frame (t1, t2, n).
    void completeFrame(const Eigen::Vector3d & n, Eigen::Vector3d & t1, Eigen::Vector3d & t2)
    {
      const Eigen::Vector3d seed =
        std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
      t1 = (seed - seed.dot(n) * n).normalized();
      t2 = n.cross(t1);
    }

    // The world point Jacobian row e^T (J_lin + J_ang x p) of body `joint` at the world point
    // p, written into row (data.J: the world Jacobian of computeJointJacobians).
    template<typename Row>
    void writePointRow(
      const pinocchio::Model & model,
      const pinocchio::Data & data,
      pinocchio::JointIndex joint,
      const Eigen::Vector3d & p,
      const Eigen::Vector3d & e,
      Row && row)
    {
      row.setZero();
      // e.(v + w x p) = e.v + w.(p x e)
      const Eigen::Vector3d pe = p.cross(e);
      for (pinocchio::JointIndex j = joint; j > 0; j = model.parents[j])
        for (int m = model.idx_vs[j]; m < model.idx_vs[j] + model.nvs[j]; ++m)
          row[m] = e.dot(data.J.col(m).head<3>()) + pe.dot(data.J.col(m).tail<3>());
    }

    // Solves of a step's impulses at most, each with the pairs and stops the last one's
    // velocities close (ContactStepper::apply).
    constexpr int kMaxContactRounds = 4;

    // The Cholesky factors of the mass matrix at q (crba fills its upper triangle).
    void factorMassMatrix(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      Eigen::LLT<Eigen::MatrixXd> & llt)
    {
      prebuilt::crba(model, data, q);
      data.M.triangularView<Eigen::StrictlyLower>() = data.M.transpose();
      llt.compute(data.M);
    }

    // Whether a force (t1, t2, n) lies strictly inside the cone of friction mu.
    bool insideCone(const Eigen::Vector3d & f, double mu)
    {
      return f.head<2>().norm() < mu * f[2] * (1. - 1e-9);
    }

  } // namespace

  // --- GroundContacts ---------------------------------------------------------------------------

  GroundContacts::GroundContacts(const pinocchio::Model & model)
  : model_(model)
  {
  }

  void GroundContacts::addPlane(
    const std::string & name,
    const Eigen::Vector3d & point,
    const Eigen::Vector3d & normal,
    double friction)
  {
    if (!point.allFinite())
      throwContactError("ground", name, "its point must be finite (m)");
    const double length = normal.norm();
    if (!(length > 1e-12) || !std::isfinite(length))
    {
      std::ostringstream msg;
      msg << "its normal must have a non-zero finite length, got (" << normal.transpose() << ")";
      throwContactError("ground", name, msg.str());
    }
    checkFriction(name, friction);
    Ground plane{name, Ground::Shape::Plane, point, {}, Eigen::Vector3d::Zero(), friction};
    Eigen::Vector3d t1, t2;
    const Eigen::Vector3d n = normal / length;
    completeFrame(n, t1, t2);
    plane.axes << t1, t2, n;
    grounds_.push_back(plane);
  }

  void GroundContacts::addBox(
    const std::string & name,
    const Eigen::Vector3d & centre,
    const Eigen::Matrix3d & axes,
    const Eigen::Vector3d & half_size,
    double friction)
  {
    if (!centre.allFinite())
      throwContactError("ground", name, "its centre must be finite (m)");
    if (
      !axes.allFinite() || !(axes.transpose() * axes).isIdentity(1e-9)
      || !(axes.determinant() > 0.))
      throwContactError("ground", name, "its axes must be a rotation matrix");
    if (!half_size.allFinite() || !(half_size.minCoeff() > 0.))
    {
      std::ostringstream msg;
      msg << "its half sizes must be finite and > 0 (m), got (" << half_size.transpose() << ")";
      throwContactError("ground", name, msg.str());
    }
    checkFriction(name, friction);
    grounds_.push_back(Ground{name, Ground::Shape::Box, centre, axes, half_size, friction});
  }

  void GroundContacts::addPoint(
    const std::string & name,
    pinocchio::JointIndex joint,
    const Eigen::Vector3d & position,
    double radius)
  {
    if (joint == 0 || joint >= static_cast<pinocchio::JointIndex>(model_.njoints))
      throwContactError(
        "contact", name,
        "its body must be moved by a joint (1 to " + std::to_string(model_.njoints - 1) + "), got "
          + std::to_string(joint));
    if (!position.allFinite())
      throwContactError("contact", name, "its point must be finite (m)");
    if (!(radius >= 0.) || !std::isfinite(radius))
      throwContactError(
        "contact", name, "radius must be finite and >= 0 (m), got " + std::to_string(radius));
    points_.push_back(Point{name, joint, position, radius});
  }

  // --- Geometry and impulses --------------------------------------------------------------------

  void touchGround(
    const GroundContacts::Ground & ground,
    const Eigen::Vector3d & centre,
    double radius,
    double & gap,
    Eigen::Ref<Eigen::Vector3d> point,
    Eigen::Ref<Eigen::Matrix3d> axes)
  {
    if (ground.shape == GroundContacts::Ground::Shape::Plane)
    {
      const auto n = ground.axes.col(2);
      gap = n.dot(centre - ground.point) - radius;
      point = centre - radius * n;
      axes = ground.axes;
      return;
    }
    // In the box's frame: outside, the direction from its closest point; inside, the normal
    // of the face nearest (the way out).
    const Eigen::Vector3d x = ground.axes.transpose() * (centre - ground.point);
    const Eigen::Vector3d & h = ground.half_size;
    const Eigen::Vector3d out = x - x.cwiseMax(-h).cwiseMin(h);
    const double distance = out.norm();
    Eigen::Vector3d n;
    if (distance > 0.)
    {
      n = out / distance;
      gap = distance - radius;
    }
    else
    {
      Eigen::Index face = 0;
      (h - x.cwiseAbs()).minCoeff(&face);
      n = Eigen::Vector3d::Unit(face) * (x[face] < 0. ? -1. : 1.);
      gap = -(h[face] - std::abs(x[face])) - radius;
    }
    n = ground.axes * n;
    point = centre - radius * n;
    Eigen::Vector3d t1, t2;
    completeFrame(n, t1, t2);
    axes << t1, t2, n;
  }

  void computeContactGeometry(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    ContactGeometry & geometry)
  {
    const int pairs = contacts.pairs();
    geometry.gap.resize(pairs);
    geometry.point.resize(3, pairs);
    geometry.axes.resize(3, 3 * pairs);
    geometry.jacobian.resize(3 * pairs, model.nv);
    pinocchio::computeJointJacobians(model, data, q);
    int k = 0;
    for (const GroundContacts::Point & s : contacts.points())
    {
      const Eigen::Vector3d centre = data.oMi[s.joint].act(s.position);
      for (const GroundContacts::Ground & ground : contacts.grounds())
      {
        auto axes = geometry.axes.middleCols<3>(3 * k);
        touchGround(ground, centre, s.radius, geometry.gap[k], geometry.point.col(k), axes);
        const Eigen::Vector3d x = geometry.point.col(k);
        for (int r = 0; r < 3; ++r)
          writePointRow(
            model, data, s.joint, x, axes.col(r).eval(), geometry.jacobian.row(3 * k + r));
        ++k;
      }
    }
  }

  bool isClearOfGrounds(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q)
  {
    ContactGeometry geometry;
    computeContactGeometry(model, data, contacts, q, geometry);
    return contacts.pairs() == 0 || geometry.gap.minCoeff() >= -kContactGapTolerance;
  }

  // --- The step ---------------------------------------------------------------------------------

  ContactStepper::ContactStepper(const GroundContacts & contacts, const JointStops * stops)
  : contacts_(contacts)
  , stops_(stops)
  , llt_(contacts.model().nv) // made in place: a moved-in LLT reads as uninitialized to GCC
  {
    const int stop_count = stops != nullptr ? static_cast<int>(stops->stops().size()) : 0;
    stop_sign_.resize(stop_count);
    stop_impulse_.resize(stop_count);
    stop_gap_.resize(stop_count);
    const int rows = 3 * contacts.pairs() + stop_count;
    const int nv = contacts.model().nv;
    geometry_.gap.resize(contacts.pairs());
    geometry_.point.resize(3, contacts.pairs());
    geometry_.axes.resize(3, 3 * contacts.pairs());
    body_velocity_.resize(6, contacts.model().njoints);
    active_.reserve(contacts.pairs());
    is_active_.resize(contacts.pairs());
    force_ = Eigen::VectorXd::Zero(3 * contacts.pairs());
    Ja_.resize(rows, nv);
    Y_.resize(nv, rows);
    b_.resize(rows);
    lambda_.resize(rows);
    mu_.resize(contacts.pairs());
    vfree_.resize(nv);
    vnext_.resize(nv);
    dv_.resize(nv);
  }

  void ContactStepper::start()
  {
    force_.setZero();
  }

  void ContactStepper::apply(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    Eigen::VectorXd & ddq,
    double h)
  {
    vfree_ = v + h * ddq;
    pinocchio::computeJointJacobians(model, data, q);
    findClosingPairs(model, data, h);
    stop_sign_.setZero();
    if (!addClosingStops(q, vfree_, h) && active_.empty())
      return;
    factorMassMatrix(model, data, q, llt_);
    // The impulses change the velocities of bodies that no row holds: a pair or stop that
    // opens at vfree_ may close at the velocity after them (talos falling on its collision
    // shapes sank a hand 2 to 4 cm in a step, and pushing that out within the next one added
    // energy until the step was rolled back). Those join and the impulses are solved again.
    for (int round = 1;; ++round)
    {
      const Eigen::Index rows = assembleRows(model, data, h);
      auto lambda = lambda_.head(rows);
      solveContactImpulses(
        Y_.leftCols(rows), b_.head(rows), mu_.head(activeCount()), lambda, impulses_, round_off_);
      dv_ = impulses_.w;
      llt_.matrixU().solveInPlace(dv_);
      keepImpulses(h);
      vnext_ = vfree_ + dv_;
      if (round == kMaxContactRounds)
        break;
      const bool pairs_added = addClosingPairs(model, data, vnext_, h);
      if (!addClosingStops(q, vnext_, h) && !pairs_added)
        break;
    }
    ddq += dv_ / h;
  }

  Eigen::Index ContactStepper::activeCount() const
  {
    return static_cast<Eigen::Index>(active_.size());
  }

  Eigen::Index ContactStepper::assembleRows(
    const pinocchio::Model & model, const pinocchio::Data & data, double h)
  {
    const Eigen::Index a = activeCount();
    for (Eigen::Index k = 0; k < a; ++k)
    {
      const int p = active_[static_cast<std::size_t>(k)];
      const pinocchio::JointIndex joint = contacts_.pointOf(p).joint;
      const Eigen::Vector3d x = geometry_.point.col(p);
      for (int r = 0; r < 3; ++r)
        writePointRow(
          model, data, joint, x, geometry_.axes.col(3 * p + r).eval(), Ja_.row(3 * k + r));
      mu_[k] = contacts_.groundOf(p).friction;
      lambda_.segment<3>(3 * k) = h * force_.segment<3>(3 * p);
      // Open: close the gap in this step and no more; sunk in (round-off, a stop's clamp):
      // come out within the step. Coming out by a fifth per step left go1's feet 1e-5 m deep
      // when the damping had taken the energy below its limit.
      b_[3 * k + 2] = geometry_.gap[p] / h;
      b_.segment<2>(3 * k).setZero();
    }
    Eigen::Index row = 3 * a;
    for (Eigen::Index i = 0; i < stop_sign_.size(); ++i)
    {
      if (stop_sign_[i] == 0.)
        continue;
      Ja_.row(row).setZero();
      Ja_(row, stops_->stops()[static_cast<std::size_t>(i)].iv) = stop_sign_[i];
      lambda_[row] = stop_impulse_[i];
      b_[row] = stop_gap_[i] / h;
      ++row;
    }
    const auto J = Ja_.topRows(row);
    Y_.leftCols(row) = J.transpose();
    llt_.matrixL().solveInPlace(Y_.leftCols(row));
    b_.head(row).noalias() += J * vfree_;
    // What round-off leaves in J vfree: the sum of |J_ij vfree_j| over a row, some 50 ulps of it.
    round_off_ = 0.;
    for (Eigen::Index r = 0; r < row; ++r)
      round_off_ = std::max(round_off_, J.row(r).cwiseAbs().dot(vfree_.cwiseAbs()));
    round_off_ *= 1e-14;
    return row;
  }

  void ContactStepper::keepImpulses(double h)
  {
    const Eigen::Index a = activeCount();
    for (Eigen::Index k = 0; k < a; ++k)
      force_.segment<3>(3 * active_[static_cast<std::size_t>(k)]) = lambda_.segment<3>(3 * k) / h;
    Eigen::Index row = 3 * a;
    for (Eigen::Index i = 0; i < stop_sign_.size(); ++i)
      if (stop_sign_[i] != 0.)
        stop_impulse_[i] = lambda_[row++];
  }

  void ContactStepper::computeBodyVelocities(
    const pinocchio::Model & model, const pinocchio::Data & data, const Eigen::VectorXd & v)
  {
    body_velocity_.col(0).setZero();
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
      body_velocity_.col(static_cast<Eigen::Index>(j)).noalias() =
        body_velocity_.col(static_cast<Eigen::Index>(model.parents[j]))
        + data.J.middleCols(model.idx_vs[j], model.nvs[j])
            * v.segment(model.idx_vs[j], model.nvs[j]);
  }

  bool ContactStepper::closesWithin(int p, double h) const
  {
    const auto V = body_velocity_.col(static_cast<Eigen::Index>(contacts_.pointOf(p).joint));
    const Eigen::Vector3d x = geometry_.point.col(p);
    const double un = geometry_.axes.col(3 * p + 2).dot(V.head<3>() + V.tail<3>().cross(x));
    return geometry_.gap[p] + h * std::min(0., un) <= 0.;
  }

  void ContactStepper::findClosingPairs(
    const pinocchio::Model & model, const pinocchio::Data & data, double h)
  {
    int p = 0;
    for (const GroundContacts::Point & s : contacts_.points())
    {
      const Eigen::Vector3d centre = data.oMi[s.joint].act(s.position);
      for (const GroundContacts::Ground & ground : contacts_.grounds())
      {
        auto axes = geometry_.axes.middleCols<3>(3 * p);
        touchGround(ground, centre, s.radius, geometry_.gap[p], geometry_.point.col(p), axes);
        ++p;
      }
    }
    active_.clear();
    std::fill(is_active_.begin(), is_active_.end(), 0);
    addClosingPairs(model, data, vfree_, h);
  }

  bool ContactStepper::addClosingPairs(
    const pinocchio::Model & model,
    const pinocchio::Data & data,
    const Eigen::VectorXd & velocity,
    double h)
  {
    // Each body's velocity (world axes, at the origin), from its joints' columns: the normal
    // velocities of all candidates for the price of one pass; the Jacobian rows are written
    // only for the pairs that close (go1 on its 404 collision points: 228 us a step with every
    // pair's rows).
    computeBodyVelocities(model, data, velocity);
    bool added = false;
    for (int p = 0; p < contacts_.pairs(); ++p)
    {
      if (is_active_[static_cast<std::size_t>(p)])
        continue;
      if (closesWithin(p, h))
      {
        is_active_[static_cast<std::size_t>(p)] = 1;
        active_.push_back(p);
        added = true;
      }
      else
        force_.segment<3>(3 * p).setZero();
    }
    return added;
  }

  bool ContactStepper::addClosingStops(
    const Eigen::VectorXd & q, const Eigen::VectorXd & velocity, double h)
  {
    bool added = false;
    for (Eigen::Index i = 0; i < stop_sign_.size(); ++i)
    {
      if (stop_sign_[i] != 0.)
        continue;
      const JointStops::Stop & s = stops_->stops()[static_cast<std::size_t>(i)];
      const double to_lower = q[s.iq] - s.lower, to_upper = s.upper - q[s.iq];
      if (to_lower + h * std::min(0., velocity[s.iv]) <= 0.)
        stop_sign_[i] = 1., stop_gap_[i] = to_lower;
      else if (to_upper + h * std::min(0., -velocity[s.iv]) <= 0.)
        stop_sign_[i] = -1., stop_gap_[i] = to_upper;
      else
        continue;
      stop_impulse_[i] = 0.;
      added = true;
    }
    return added;
  }

  bool ContactStepper::addStopsReached(
    const Eigen::VectorXd & q, std::vector<pinocchio::JointIndex> * hits) const
  {
    bool reached = false;
    for (Eigen::Index i = 0; i < stop_sign_.size(); ++i)
    {
      if (stop_sign_[i] == 0. || stop_gap_[i] <= kContactGapTolerance)
        continue;
      const JointStops::Stop & s = stops_->stops()[static_cast<std::size_t>(i)];
      if (q[s.iq] != (stop_sign_[i] > 0. ? s.lower : s.upper))
        continue;
      reached = true;
      if (hits != nullptr && std::find(hits->begin(), hits->end(), s.joint) == hits->end())
        hits->push_back(s.joint);
    }
    return reached;
  }

  // --- A rest -----------------------------------------------------------------------------------

  namespace
  {
    // The Jacobian rows (t1, t2, n) of the given pairs, stacked (3 per pair x nv).
    Eigen::MatrixXd stackPairRows(const ContactGeometry & geometry, const std::vector<int> & pairs)
    {
      Eigen::MatrixXd J(3 * static_cast<Eigen::Index>(pairs.size()), geometry.jacobian.cols());
      for (std::size_t k = 0; k < pairs.size(); ++k)
        J.middleRows<3>(3 * static_cast<Eigen::Index>(k)) =
          geometry.jacobian.middleRows<3>(3 * pairs[k]);
      return J;
    }

    // Whether the pairs' forces (the first 3 mu.size() entries of x: t1, t2, n each) lie in
    // their cones shrunk by shrink.
    bool insideCones(const Eigen::VectorXd & mu, const Eigen::VectorXd & x, double shrink)
    {
      for (Eigen::Index k = 0; k < mu.size(); ++k)
      {
        const Eigen::Index r = 3 * k;
        if (x.segment<2>(r).norm() > shrink * mu[k] * x[r + 2] * (1. + 1e-9) + 1e-12 * x.norm())
          return false;
      }
      return true;
    }

    // The projection of f (t1, t2, n) onto the cone of friction mu.
    Eigen::Vector3d projectOntoCone(const Eigen::Vector3d & f, double mu)
    {
      const double t = f.head<2>().norm(), n = f[2];
      if (t <= mu * n)
        return f;
      if (mu * t <= -n)
        return Eigen::Vector3d::Zero();
      const double along = (mu * t + n) / (mu * mu + 1.);
      return Eigen::Vector3d(f[0] * mu * along / t, f[1] * mu * along / t, along);
    }

    // The supports' share x (3 per pair, then 1 per stop) that balances what x balances (the
    // least-squares set of A x = load, A = [J^T E]) with the pairs' forces inside their cones
    // shrunk by kMarginalCone and the stops pushing, found by alternating projections from x
    // between that set and cones a tenth of the margin smaller still (so that the iterates enter
    // the shrunk cones in finitely many steps): whether it was found (then x holds it). Least
    // norm and the projected Gauss-Seidel of the mass metric stopped short of the inside of the
    // cones on solo12 lying on eleven of its collision points, where a linear programme found
    // forces 1 % inside: its rest read as sliding, hence unstable. The stops' share is solved
    // with the pairs': held at its least-norm value, talos lying with its knees on their stops
    // found no forces in the cones and kept 0.9 N m unbalanced.
    bool findForcesInsideCones(
      const Eigen::MatrixXd & A,
      const Eigen::VectorXd & mu,
      const Eigen::VectorXd & load,
      Eigen::VectorXd & x)
    {
      Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(A.rows(), A.cols());
      cod.setThreshold(1e-10);
      cod.compute(A);
      const Eigen::MatrixXd pinv = cod.pseudoInverse();
      const double target = 1. - 1.1 * kMarginalCone;
      const Eigen::Index pair_rows = 3 * mu.size();
      constexpr int kMaxProjections = 20000;
      Eigen::VectorXd p(x.size()), moved(x.size());
      for (int it = 0; it < kMaxProjections; ++it)
      {
        if (insideCones(mu, x, 1. - kMarginalCone))
          return true;
        for (Eigen::Index k = 0; k < mu.size(); ++k)
          p.segment<3>(3 * k) = projectOntoCone(x.segment<3>(3 * k), target * mu[k]);
        p.tail(x.size() - pair_rows) = x.tail(x.size() - pair_rows).cwiseMax(0.);
        moved = p - pinv * (A * p - load) - x;
        x += moved;
        // Stalled: the two sets do not meet, the iterates settle on the points closest
        // between them (go1 with its feet slid to their cones' edge ran all 20,000 at every
        // assessment: 42.7 to 144 ms a solve).
        if (moved.lpNorm<Eigen::Infinity>() <= 1e-12 * x.lpNorm<Eigen::Infinity>())
          return false;
      }
      return false;
    }

    // The supports' share x (as findForcesInsideCones) in the cones, with the stops pushing,
    // closest to balancing tau in the mass metric (the step's problem at zero velocity), when
    // none inside the shrunk cones balances it.
    Eigen::VectorXd conicForces(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::MatrixXd & A,
      const Eigen::VectorXd & mu,
      const Eigen::VectorXd & tau,
      Eigen::VectorXd x)
    {
      Eigen::LLT<Eigen::MatrixXd> llt(model.nv);
      factorMassMatrix(model, data, q, llt);
      const Eigen::MatrixXd Y = llt.matrixL().solve(A);
      // Velocity after a unit time from rest: M^-1 (A x - tau); u = Y^T Y x - A^T M^-1 tau.
      const Eigen::VectorXd b = -(Y.transpose() * llt.matrixL().solve(tau));
      for (Eigen::Index k = 0; k < mu.size(); ++k)
        x[3 * k + 2] = std::max(x[3 * k + 2], 0.);
      x.tail(x.size() - 3 * mu.size()) = x.tail(x.size() - 3 * mu.size()).cwiseMax(0.);
      ImpulseWorkspace work;
      solveContactImpulses(Y, b, mu, x, work);
      return x;
    }
  } // namespace

  namespace
  {
    // The columns of the supports' generalized forces, A = [J^T E]: 3 per pair (t1, t2, n),
    // then 1 per stop (the direction it pushes its joint).
    Eigen::MatrixXd supportMatrix(
      const ContactGeometry & geometry,
      const std::vector<int> & pairs,
      const std::vector<StopReached> & on)
    {
      const Eigen::Index p = 3 * static_cast<Eigen::Index>(pairs.size());
      Eigen::MatrixXd A =
        Eigen::MatrixXd::Zero(geometry.jacobian.cols(), p + static_cast<Eigen::Index>(on.size()));
      A.leftCols(p) = stackPairRows(geometry, pairs).transpose();
      for (std::size_t k = 0; k < on.size(); ++k)
        A(on[k].stop->iv, p + static_cast<Eigen::Index>(k)) = on[k].sign();
      return A;
    }

    // Least-norm forces of the pairs and reactions of the stops with A x = tau, by least
    // squares.
    Eigen::VectorXd leastNormSupport(const Eigen::MatrixXd & A, const Eigen::VectorXd & tau)
    {
      if (A.cols() == 0)
        return Eigen::VectorXd(0); // nothing supports: Eigen's decomposition of no column fails
      // The cut is set before the decomposition: the rank it gives decides the Z factor, and a
      // cut set afterwards had solve() apply Z for a rank it was never computed for (reading
      // uninitialised memory: the same rest gave 66 to 55,296 steps).
      Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(A.rows(), A.cols());
      cod.setThreshold(1e-10);
      cod.compute(A);
      return cod.solve(tau);
    }

    // The support that pulls hardest (a normal force or a stop's reaction below -tiny), let go
    // of: whether there was one.
    bool releasePulling(
      const Eigen::VectorXd & x,
      std::vector<int> & pairs,
      std::vector<StopReached> & on,
      double tiny)
    {
      const Eigen::Index p = 3 * static_cast<Eigen::Index>(pairs.size());
      Eigen::Index worst = -1;
      double least = -tiny;
      for (Eigen::Index k = 0; k < static_cast<Eigen::Index>(pairs.size()); ++k)
        if (x[3 * k + 2] < least)
          least = x[3 * k + 2], worst = k;
      for (Eigen::Index k = 0; k < static_cast<Eigen::Index>(on.size()); ++k)
        if (x[p + k] < least)
          least = x[p + k], worst = static_cast<Eigen::Index>(pairs.size()) + k;
      if (worst < 0)
        return false;
      if (worst < static_cast<Eigen::Index>(pairs.size()))
        pairs.erase(pairs.begin() + worst);
      else
        on.erase(on.begin() + (worst - static_cast<Eigen::Index>(pairs.size())));
      return true;
    }
  } // namespace

  ContactBalance balanceContacts(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau,
    const JointStops * stops)
  {
    ContactBalance balance;
    balance.force = Eigen::VectorXd::Zero(3 * contacts.pairs());
    ContactGeometry & geometry = balance.geometry;
    computeContactGeometry(model, data, contacts, q, geometry);
    for (int p = 0; p < contacts.pairs(); ++p)
      if (geometry.gap[p] <= kContactGapTolerance)
        balance.closed.push_back(p);
    // Active set: a support the least-norm balance would pull on lets go, one at a time.
    std::vector<int> pairs = balance.closed;
    // A joint on its stop: its reaction is one more unknown, sign e_iv its column. Within
    // kContactGapTolerance of it, as the step lands it (enforceStops) and as a Newton step held
    // on it leaves it (a round-off inside: talos's knee reaction went missing, 27 N m).
    std::vector<StopReached> on = stops != nullptr
                                    ? findStopsReached(*stops, q, kContactGapTolerance)
                                    : std::vector<StopReached>();
    Eigen::MatrixXd A;
    Eigen::VectorXd x;
    const double tiny = 1e-12 * std::max(tau.lpNorm<Eigen::Infinity>(), 1e-300);
    do
    {
      A = supportMatrix(geometry, pairs, on);
      x = leastNormSupport(A, tau);
    } while (releasePulling(x, pairs, on, tiny));
    Eigen::VectorXd mu(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k)
      mu[static_cast<Eigen::Index>(k)] = contacts.groundOf(pairs[k]).friction;
    if (!insideCones(mu, x, 1. - kMarginalCone))
    {
      // Least norm shares the tangential force evenly and may leave a lightly loaded point's
      // cone where other shares stay inside every cone (a box on a slope, its upper corners):
      // first cones shrunk by kMarginalCone, whose answer sticks, else the cones themselves
      // (then the rest is within kMarginalCone of sliding).
      const Eigen::VectorXd start = x;
      balance.near_cone_edge = !findForcesInsideCones(A, mu, tau, x);
      if (balance.near_cone_edge)
        x = conicForces(model, data, q, A, mu, tau, start);
    }
    const Eigen::Index p = 3 * static_cast<Eigen::Index>(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k)
      balance.force.segment<3>(3 * pairs[k]) = x.segment<3>(3 * static_cast<Eigen::Index>(k));
    for (std::size_t k = 0; k < on.size(); ++k)
      balance.stops.push_back(
        StopContact{on[k].stop->joint, on[k].side, x[p + static_cast<Eigen::Index>(k)]});
    balance.left = tau - A * x;
    balance.residual = balance.left.lpNorm<Eigen::Infinity>();
    return balance;
  }

  namespace
  {
    // The rows held at a rest: all three of a pair that carries a force; none of a pair that
    // carries nothing. At rest nothing slips: friction holds a contact anywhere in its closed
    // cone, at its edge too (how near that edge is the marginal verdict's: describeContacts).
    // Let slide at the edge, a box resting within 1 % of its steepest slope read as unstable,
    // was pushed, stuck again, and was pushed for 90 s.
    std::vector<Eigen::Index> heldRows(const ContactBalance & balance, double tiny)
    {
      std::vector<Eigen::Index> rows;
      for (const int p : balance.closed)
        if (balance.force[3 * p + 2] > tiny)
          for (Eigen::Index r = 3 * p; r < 3 * p + 3; ++r)
            rows.push_back(r);
      return rows;
    }

    Eigen::MatrixXd selectRows(const Eigen::MatrixXd & J, const std::vector<Eigen::Index> & rows)
    {
      Eigen::MatrixXd out(static_cast<Eigen::Index>(rows.size()), J.cols());
      for (std::size_t k = 0; k < rows.size(); ++k)
        out.row(static_cast<Eigen::Index>(k)) = J.row(rows[k]);
      return out;
    }

    // An orthonormal basis of the motions the rows of Jh leave free (dim nv x free).
    Eigen::MatrixXd nullSpace(const Eigen::MatrixXd & Jh, Eigen::Index nv)
    {
      if (Jh.rows() == 0)
        return Eigen::MatrixXd::Identity(nv, nv);
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(Jh, Eigen::ComputeFullV);
      const Eigen::VectorXd & s = svd.singularValues();
      const double cut = 1e-10 * std::max(s[0], 1e-300);
      Eigen::Index rank = 0;
      while (rank < s.size() && s[rank] > cut)
        ++rank;
      return svd.matrixV().rightCols(nv - rank);
    }
    // The contact forces' stiffness d(J^T f)/dq along the motions N (dim nv x N.cols()), f held
    // on the rows; the rows follow the gap function (the contact point moves over a sphere as
    // it turns), by central differences.
    Eigen::MatrixXd contactForceStiffness(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const GroundContacts & contacts,
      const Eigen::VectorXd & q,
      const std::vector<Eigen::Index> & rows,
      const Eigen::VectorXd & f,
      const Eigen::MatrixXd & N)
    {
      const double h = 1e-6;
      Eigen::MatrixXd C(model.nv, N.cols());
      Eigen::VectorXd q_plus(model.nq), q_minus(model.nq);
      ContactGeometry plus, minus;
      for (Eigen::Index k = 0; k < N.cols(); ++k)
      {
        pinocchio::integrate(model, q, (h * N.col(k)).eval(), q_plus);
        pinocchio::integrate(model, q, (-h * N.col(k)).eval(), q_minus);
        computeContactGeometry(model, data, contacts, q_plus, plus);
        computeContactGeometry(model, data, contacts, q_minus, minus);
        C.col(k) = (selectRows(plus.jacobian, rows).transpose() * f
                    - selectRows(minus.jacobian, rows).transpose() * f)
                   / (2. * h);
      }
      return C;
    }
  } // namespace

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const JointStops * stops)
  {
    const Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
    const ContactBalance balance = balanceContacts(model, data, contacts, q, tau, stops);
    const double tiny = 1e-9 * std::max(tau.lpNorm<Eigen::Infinity>(), 1e-300);
    const std::vector<Eigen::Index> rows = heldRows(balance, tiny);
    // The joints pressed on a stop are held too (their rows have no curvature).
    Eigen::MatrixXd Jh = selectRows(balance.geometry.jacobian, rows);
    for (const StopContact & c : balance.stops)
      if (c.reaction > tiny)
      {
        Jh.conservativeResize(Jh.rows() + 1, Eigen::NoChange);
        Jh.row(Jh.rows() - 1).setZero();
        Jh(Jh.rows() - 1, model.idx_vs[c.joint]) = 1.;
      }
    const Eigen::MatrixXd N = nullSpace(Jh, model.nv);
    if (N.cols() == 0)
    {
      // Held in every motion by contacts that press: a push lifts the body off them.
      StabilityReport report = assessStiffness(Eigen::MatrixXd(0, 0), 1e-7);
      report.verdict = Stability::Stable;
      report.basis = N;
      return report;
    }
    Eigen::VectorXd f(static_cast<Eigen::Index>(rows.size()));
    for (std::size_t k = 0; k < rows.size(); ++k)
      f[static_cast<Eigen::Index>(k)] = balance.force[rows[k]];
    const Eigen::MatrixXd K = computeStiffnessMatrix(model, data, q, forces);
    const Eigen::MatrixXd C = contactForceStiffness(model, data, contacts, q, rows, f, N);
    const Eigen::MatrixXd KN = K * N;
    const Eigen::MatrixXd reduced = N.transpose() * (KN - C);
    // Where gravity's stiffness and the contacts' cancel (a ball on a floor), what is left is
    // the round-off of the differences: eigenvalues within 1e-7 of the terms count as zero.
    const double terms = std::max(KN.lpNorm<Eigen::Infinity>(), C.lpNorm<Eigen::Infinity>());
    StabilityReport report =
      assessStiffness(reduced, 1e-7, std::max(computeStiffnessFloor(model, true), 1e-7 * terms));
    report.softest_direction = N * report.softest_direction;
    report.basis = N;
    return report;
  }

  std::vector<GroundContact> describeContacts(
    const GroundContacts & contacts, const ContactBalance & balance, double load)
  {
    const ContactGeometry & geometry = balance.geometry;
    std::vector<GroundContact> out;
    double largest = load; // N
    for (const int p : balance.closed)
    {
      const GroundContacts::Ground & ground = contacts.groundOf(p);
      const auto axes = geometry.axes.middleCols<3>(3 * p);
      const Eigen::Vector3d f = balance.force.segment<3>(3 * p);
      GroundContact c;
      c.name = contacts.pointOf(p).name;
      c.ground = ground.name;
      c.point = geometry.point.col(p);
      c.normal = axes.col(2);
      c.normal_force = f[2];
      c.tangential_force = f[0] * axes.col(0) + f[1] * axes.col(1);
      c.gap = geometry.gap[p];
      c.sticking = insideCone(f, ground.friction) || f.head<2>().isZero(0.);
      c.marginal = balance.near_cone_edge && !f.head<2>().isZero(0.)
                   && f.head<2>().norm() >= (1. - kMarginalCone) * ground.friction * f[2];
      largest = std::max(largest, c.normal_force);
      out.push_back(c);
    }
    for (GroundContact & c : out)
      c.marginal = c.marginal || c.normal_force <= kMarginalLoad * largest;
    return out;
  }

} // namespace pinsettle
