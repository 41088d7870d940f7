//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/step-control.hpp"
#include "pinsettle/statics.hpp"

#include <pinocchio/algorithm/aba.hpp>
#include "pinsettle/prebuilt.hpp"
#include <pinocchio/algorithm/joint-configuration.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace pinsettle
{

  void integrateSemiImplicitEuler(
    const pinocchio::Model & model,
    const Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    const Eigen::VectorXd & a,
    double h,
    Eigen::VectorXd & dq,
    Eigen::VectorXd & q_next)
  {
    v.noalias() += h * a;
    dq.noalias() = h * v;
    pinocchio::integrate(model, q, dq, q_next);
  }

  Eigen::VectorXd computeJointInertia(
    const Eigen::MatrixXd & K, const Eigen::VectorXd & mass_diagonal, const Eigen::VectorXd & tau)
  {
    const Eigen::Index n = mass_diagonal.size();
    Eigen::VectorXd added = Eigen::VectorXd::Zero(n);
    const Eigen::VectorXd rate = K.diagonal().cwiseAbs().cwiseMax(tau.cwiseAbs());
    const double floor = kJointRateFloor * rate.maxCoeff();
    const auto counts = [&](Eigen::Index i) { return rate[i] > floor && mass_diagonal[i] > 0.; };
    double slowest = std::numeric_limits<double>::infinity(), fastest = 0.;
    for (Eigen::Index i = 0; i < n; ++i)
      if (counts(i))
      {
        slowest = std::min(slowest, rate[i] / mass_diagonal[i]);
        fastest = std::max(fastest, rate[i] / mass_diagonal[i]);
      }
    if (!(fastest > 0.))
      return added; // nothing pulls or holds: no rate to match
    const double target = std::max(slowest, fastest / kJointInertiaSpread);
    for (Eigen::Index i = 0; i < n; ++i)
      if (counts(i))
        added[i] = std::max(rate[i] / target - mass_diagonal[i], 0.);
    return added;
  }

  StepController::StepController(
    const pinocchio::Model & model, const LoopConstraints * loops, bool stiff_modes)
  : model_(model)
  , loops_(loops)
  , stiff_modes_allowed_(stiff_modes)
  , q_estimate_(model.nq)
  , moved_(model.nv)
  , a_(model.nv)
  {
  }

  void StepController::start(const Settings & settings, const ForceModel * forces)
  {
    // One joint has no other to be slowed to; the simplified energy does not see the added
    // inertia, so its peaks would not be those of the scaled motion. Stiff-mode scaling is
    // refused exactly where there are ground contacts.
    scale_joint_inertia_ = effectiveJointInertia(settings, model_.nv, !stiff_modes_allowed_)
                           && loops_ == nullptr && settings.dt == 0.
                           && settings.energy == EnergyMeasure::Exact && model_.nv > 1;
    inertia_active_ = false;
    scaled_model_current_ = false;
    ++dynamics_version_;
    scaled_joints_ = 0;
    if (scale_joint_inertia_)
      joint_inertia_.setZero(model_.nv);
    else
      joint_inertia_.resize(0);
    forces_ = forces;
    automatic_ = settings.dt == 0.;
    scale_stiff_modes_ = settings.scale_stiff_modes && stiff_modes_allowed_;
    dt_safety_ = effectiveDtSafety(settings);
    dt_ = settings.dt;
    h_ = dt_;
    growth_ = 1.;
    max_growth_ = std::min(effectiveDtGrowth(settings), 1. / dt_safety_); // both >= 1
    step_scale_ = 1.;
    estimated_at_ = 0;
    estimate_spacing_ =
      std::max<std::int64_t>(settings.ds, static_cast<std::int64_t>(model_.nv) * model_.nv / 4);
    estimates_ = 0;
    scaled_modes_ = 0;
    time_scale_ = TimeScale(); // no stiff-mode scaling with a fixed step
  }

  double StepController::kineticEnergyOfAdded(
    const TimeScale & scale, const Eigen::VectorXd & v) const
  {
    double e = inertia_active_ ? 0.5 * v.cwiseAbs2().dot(joint_inertia_) : 0.;
    if (scale.stiff_masses.size() > 0)
      e += 0.5 * (scale.stiff_momenta * v).cwiseAbs2().dot(scale.stiff_masses);
    return e;
  }

  TimeScale StepController::estimateTimeScale(pinocchio::Data & data, const Eigen::VectorXd & q)
  {
    if (loops_ != nullptr)
      return computeTimeScale(model_, data, *loops_, q, forces_);
    if (!scale_joint_inertia_)
      return computeTimeScale(model_, data, q, forces_, scale_stiff_modes_);
    // The added inertia from the mechanism as it is at q (its own armature included), then the
    // time scale of the mechanism that carries it.
    const Eigen::MatrixXd K = computeStiffnessMatrix(model_, data, q, forces_);
    const Eigen::VectorXd tau = computeStaticForce(model_, data, q, forces_);
    prebuilt::crba(model_, data, q);
    joint_inertia_ = computeJointInertia(K, data.M.diagonal(), tau);
    const int scaled = static_cast<int>((joint_inertia_.array() > 0.).count());
    scaled_joints_ = std::max(scaled_joints_, scaled);
    inertia_active_ = scaled > 0;
    ++dynamics_version_;
    if (inertia_active_)
    {
      if (!scaled_model_current_) // once per run: the model may have changed since the last
      {
        scaled_model_ = model_;
        scaled_model_current_ = true;
      }
      scaled_model_.armature = model_.armature + joint_inertia_;
    }
    return computeTimeScale(dynamicsModel(), data, q, forces_, scale_stiff_modes_, &K);
  }

  double StepController::estimate(
    pinocchio::Data & data, const Eigen::VectorXd & q, Eigen::VectorXd & v, std::int64_t step)
  {
    const double added_before = kineticEnergyOfAdded(time_scale_, v);
    time_scale_ = estimateTimeScale(data, q);
    const TimeScale & scale = time_scale_;
    const Eigen::Index stiff = scale.stiff_masses.size();
    const double added_after = kineticEnergyOfAdded(scale, v);
    // The energy the switch takes: none where more inertia is added (the velocity is scaled to
    // keep the energy), the removed inertia's share where some is taken away. The runaway
    // monitor counts it as removed; counting the first case too made a fall's release look
    // irregular, and with the joint inertia re-chosen along the fall it was never confirmed.
    double loss = 0.;
    if (added_after > added_before)
    {
      // data.M is fresh from computeTimeScale's crba, the joints' added inertia included.
      double real = 0.5 * v.dot(data.M.selfadjointView<Eigen::Upper>() * v);
      if (inertia_active_)
        real -= 0.5 * v.cwiseAbs2().dot(joint_inertia_);
      v *= std::sqrt((real + added_before) / (real + added_after));
    }
    else
      loss = added_before - added_after;
    scaled_modes_ = std::max(scaled_modes_, static_cast<int>(stiff));
    stiff_y_.resize(model_.nv, stiff);
    stiff_s_.resize(stiff, stiff);
    stiff_z_.resize(stiff);
    stiff_p_.resize(stiff);
    // Sized by a factorization (of the identity), not by assigning LLT(stiff): that constructor
    // leaves its info() unset, and the assignment copies the unset value (UBSan: an invalid
    // ComputationInfo).
    stiff_llt_.compute(Eigen::MatrixXd::Identity(stiff, stiff));
    double next = std::isfinite(scale.critical_step)
                    ? dt_safety_ * scale.critical_step * step_scale_
                    : kRestStep * step_scale_;
    if (estimates_ > 0)
      next = std::min(next, 2. * dt_); // grow gradually: the new estimate is local too
    dt_ = next;
    q_estimate_ = q;
    estimated_at_ = step;
    ++estimates_;
    return loss;
  }

  bool StepController::isEstimateDue(const Eigen::VectorXd & q, std::int64_t step)
  {
    if (!automatic_ || step - estimated_at_ < estimate_spacing_)
      return false;
    pinocchio::difference(model_, q_estimate_, q, moved_);
    return moved_.lpNorm<Eigen::Infinity>() > kFarMove;
  }

  double StepController::halve(
    pinocchio::Data & data, const Eigen::VectorXd & q, Eigen::VectorXd & v, std::int64_t step)
  {
    step_scale_ *= 0.5;
    dt_ *= 0.5;
    growth_ = 1.;
    if (!automatic_)
      return 0.;
    // The modes of the good state, and no longer a step than the halved one.
    const double halved = dt_;
    const double loss = estimate(data, q, v, step);
    dt_ = std::min(dt_, halved);
    return loss;
  }

  double StepController::addedEnergy(const Eigen::VectorXd & v)
  {
    double e = inertia_active_ ? 0.5 * v.cwiseAbs2().dot(joint_inertia_) : 0.;
    if (stiffModes() == 0)
      return e;
    stiff_p_.noalias() = time_scale_.stiff_momenta * v;
    return e + 0.5 * stiff_p_.cwiseAbs2().dot(time_scale_.stiff_masses);
  }

  void StepController::correctAcceleration(pinocchio::Data & data)
  {
    if (stiffModes() == 0)
      return;
    const Eigen::MatrixXd & W = time_scale_.stiff_momenta;
    a_ = data.ddq; // kept aside from computeMinverse's passes
    // data holds this step's aba on dynamicsModel(), world convention: M^-1 from its
    // articulated inertias, through the instantiation pinocchio_default carries (with q the
    // whole algorithm compiled here again, about 57 s) and without a forward pass of its own.
    pinocchio::computeMinverse(dynamicsModel(), data);
    stiff_y_.noalias() = data.Minv.selfadjointView<Eigen::Upper>() * W.transpose();
    stiff_s_.noalias() = W * stiff_y_;
    stiff_s_.diagonal() += time_scale_.stiff_masses.cwiseInverse();
    stiff_llt_.compute(stiff_s_);
    stiff_z_.noalias() = W * a_;
    stiff_llt_.solveInPlace(stiff_z_);
    data.ddq = a_;
    data.ddq.noalias() -= stiff_y_ * stiff_z_;
  }

  double StepController::nextStep(const Eigen::VectorXd & v, const Eigen::VectorXd & a)
  {
    h_ = dt_;
    if (automatic_)
    {
      // Between damping events the motion runs downhill and the step grows, as FIRE's does;
      // a damping event starts it again from the estimate (restartGrowth).
      h_ *= growth_;
      growth_ = std::min(growth_ * kStepGrowthRate, max_growth_);
      // The step moves q by h (v + h a); |v + h a| <= V + h A, and h (V + h A) <= c holds up
      // to the positive root of A h^2 + V h - c, written so that A = 0 gives c / V.
      const double speed = v.lpNorm<Eigen::Infinity>();
      const double pull = a.lpNorm<Eigen::Infinity>();
      const double bound =
        2. * dt_safety_ / (speed + std::sqrt(speed * speed + 4. * pull * dt_safety_));
      h_ = std::min(h_, bound); // bound is inf at rest with no pull, NaN never (c > 0)
    }
    return h_;
  }

} // namespace pinsettle
