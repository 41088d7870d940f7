//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/stops.hpp"
#include "pinsettle/loops.hpp"
#include "pinsettle/statics.hpp"
#include "unit-norm.hpp"

#include "pinsettle/prebuilt.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace pinsettle
{

  const char * toString(StopSide side)
  {
    return side == StopSide::Lower ? "lower" : "upper";
  }

  namespace
  {
    // Joints a stop can act on: one configuration entry, one velocity (revolute, prismatic,
    // helical), never a mimic joint (it has no motion of its own).
    bool isStoppable(const pinocchio::Model & model, pinocchio::JointIndex joint)
    {
      return model.nqs[joint] == 1 && model.nvs[joint] == 1
             && boost::get<pinocchio::JointModelMimic>(&model.joints[joint].toVariant()) == nullptr;
    }

    double asBound(double limit, double none)
    {
      return std::isfinite(limit) && std::abs(limit) < JointStops::kNoLimit ? limit : none;
    }

    constexpr double kInf = std::numeric_limits<double>::infinity();

    // Pinocchio's parsers fill the limits of joints of several entries with +-1.01 (the MJCF
    // parser on a free joint's translation too) or +-max.
    constexpr double kPlaceholderLimit = 1.01;

    // Whether a joint of several configuration entries has position limits other than
    // Pinocchio's placeholders: bounds beyond kNoLimit, +-1.01, or of magnitude 1 or more on
    // entries of unit norm, which never reach them.
    bool hasOwnLimits(
      const pinocchio::Model & model, pinocchio::JointIndex joint, const Eigen::VectorXd & neutral)
    {
      const Eigen::Array<bool, Eigen::Dynamic, 1> unit = unitNormEntries(model, joint, neutral);
      for (int k = 0; k < model.nqs[joint]; ++k)
      {
        const int iq = model.idx_qs[joint] + k;
        const double none = unit[k] ? 1. : JointStops::kNoLimit;
        for (const double bound : {model.lowerPositionLimit[iq], model.upperPositionLimit[iq]})
          if (std::isnan(bound) || (std::abs(bound) < none && std::abs(bound) != kPlaceholderLimit))
            return true;
      }
      return false;
    }
  } // namespace

  JointStops::JointStops(const pinocchio::Model & model, bool from_model)
  : model_(model)
  {
    if (!from_model)
      return;
    Eigen::VectorXd neutral; // made once a joint of several entries needs it
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    {
      if (model.nqs[j] > 1)
      {
        if (neutral.size() == 0)
          neutral = pinocchio::neutral(model);
        if (hasOwnLimits(model, j, neutral))
          unapplied_limits_.push_back(j);
      }
      if (!isStoppable(model, j))
        continue;
      const int iq = model.idx_qs[j];
      const double lower = model.lowerPositionLimit[iq], upper = model.upperPositionLimit[iq];
      if (lower == upper)
      {
        equal_limits_.push_back(j);
        continue;
      }
      const Stop stop{j, iq, model.idx_vs[j], asBound(lower, -kInf), asBound(upper, kInf)};
      if (std::isfinite(stop.lower) || std::isfinite(stop.upper))
        stops_.push_back(stop);
    }
  }

  void JointStops::setLimit(pinocchio::JointIndex joint, double lower, double upper)
  {
    std::ostringstream msg;
    if (joint == 0 || joint >= static_cast<pinocchio::JointIndex>(model_.njoints))
      msg << "joint index " << joint << " is not a joint of the model (1 to " << model_.njoints - 1
          << ")";
    else if (!isStoppable(model_, joint))
      msg << "joint '" << model_.names[joint] << "' (" << model_.joints[joint].shortname()
          << ") cannot have a stop: only revolute, prismatic and helical joints (one "
             "configuration entry) can";
    else if (std::isnan(lower) || std::isnan(upper))
      msg << "the stops of joint '" << model_.names[joint] << "' are NaN";
    else if (lower > upper)
      msg << "the stops of joint '" << model_.names[joint] << "' have lower " << lower
          << " > upper " << upper;
    if (msg.tellp() > 0)
      throw std::invalid_argument(msg.str());
    removeLimit(joint);
    const Stop stop{joint, model_.idx_qs[joint], model_.idx_vs[joint], lower, upper};
    if (std::isfinite(lower) || std::isfinite(upper))
    {
      std::vector<Stop>::iterator at = stops_.begin();
      while (at != stops_.end() && at->joint < joint)
        ++at;
      stops_.insert(at, stop);
    }
  }

  void JointStops::removeLimit(pinocchio::JointIndex joint)
  {
    for (std::vector<Stop>::iterator it = stops_.begin(); it != stops_.end(); ++it)
      if (it->joint == joint)
      {
        stops_.erase(it);
        return;
      }
  }

  double clampToStops(
    const JointStops & stops,
    Eigen::VectorXd & q,
    std::vector<std::pair<pinocchio::JointIndex, double>> * moved)
  {
    double largest = 0.;
    for (const JointStops::Stop & s : stops.stops())
    {
      const double before = q[s.iq];
      q[s.iq] = std::min(std::max(before, s.lower), s.upper);
      const double distance = std::abs(q[s.iq] - before);
      if (distance > 0.)
      {
        largest = std::max(largest, distance);
        if (moved != nullptr)
          moved->emplace_back(s.joint, distance);
      }
    }
    return largest;
  }

  bool enforceStops(
    const JointStops & stops,
    Eigen::VectorXd & q,
    Eigen::VectorXd & v,
    std::vector<pinocchio::JointIndex> * hits,
    double slack,
    Eigen::VectorXd * motion)
  {
    bool hit = false;
    for (const JointStops::Stop & s : stops.stops())
    {
      double & x = q[s.iq];
      double & rate = v[s.iv];
      const bool past = x < s.lower - slack || x > s.upper + slack;
      const double was = x;
      if (x <= s.lower + slack)
      {
        x = s.lower;
        rate = std::max(rate, 0.);
      }
      else if (x >= s.upper - slack)
      {
        x = s.upper;
        rate = std::min(rate, 0.);
      }
      if (motion != nullptr)
        (*motion)[s.iv] += x - was;
      if (past && hits != nullptr)
        hits->push_back(s.joint);
      hit = hit || past;
    }
    return hit;
  }

  std::vector<StopContact> computeStopContacts(
    const JointStops & stops, const Eigen::VectorXd & q, const Eigen::VectorXd & tau)
  {
    std::vector<StopContact> contacts;
    for (const JointStops::Stop & s : stops.stops())
    {
      if (q[s.iq] <= s.lower)
        contacts.push_back(StopContact{s.joint, StopSide::Lower, std::max(0., tau[s.iv])});
      else if (q[s.iq] >= s.upper)
        contacts.push_back(StopContact{s.joint, StopSide::Upper, std::max(0., -tau[s.iv])});
    }
    return contacts;
  }

  double computeStopResidual(
    const JointStops & stops, const Eigen::VectorXd & q, const Eigen::VectorXd & tau)
  {
    Eigen::VectorXd violation = tau.cwiseAbs();
    for (const JointStops::Stop & s : stops.stops())
    {
      if (q[s.iq] <= s.lower)
        violation[s.iv] = std::max(0., -tau[s.iv]);
      else if (q[s.iq] >= s.upper)
        violation[s.iv] = std::max(0., tau[s.iv]);
    }
    return violation.size() > 0 ? violation.maxCoeff() : 0.;
  }

  Eigen::MatrixXd computeFreeDirections(
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau,
    double tolerance)
  {
    std::vector<bool> held(static_cast<std::size_t>(tau.size()), false);
    for (const StopContact & c : computeStopContacts(stops, q, tau))
      if (c.reaction > tolerance)
        held[static_cast<std::size_t>(stops.model().idx_vs[c.joint])] = true;
    Eigen::Index free = 0;
    for (const bool h : held)
      free += h ? 0 : 1;
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(tau.size(), free);
    Eigen::Index column = 0;
    for (Eigen::Index k = 0; k < tau.size(); ++k)
      if (!held[static_cast<std::size_t>(k)])
        B(k, column++) = 1.;
    return B;
  }

  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    if (stops.empty())
      return assessStability(model, data, q, forces);
    const Eigen::VectorXd tau = computeStaticForce(model, data, q, forces);
    const double tolerance = 1e-9 * tau.lpNorm<Eigen::Infinity>();
    const Eigen::MatrixXd B = computeFreeDirections(stops, q, tau, tolerance);
    const Eigen::MatrixXd K = computeStiffnessMatrix(model, data, q, forces);
    const bool finite_differences = forces != nullptr && !forces->empty();
    StabilityReport report = assessStiffness(
      B.transpose() * K * B, finite_differences ? 1e-7 : 1e-9,
      computeStiffnessFloor(model, finite_differences));
    if (B.cols() == 0) // every joint pressed onto a stop: nothing can move
    {
      report.verdict = Stability::Stable;
      report.softest_direction = Eigen::VectorXd::Zero(model.nv);
    }
    else
      report.softest_direction = B * report.softest_direction;
    report.basis = B;
    return report;
  }

  std::vector<StopReached> findStopsReached(
    const JointStops & stops, const Eigen::VectorXd & q, double slack)
  {
    std::vector<StopReached> on;
    for (const JointStops::Stop & s : stops.stops())
    {
      if (q[s.iq] <= s.lower + slack)
        on.push_back(StopReached{&s, StopSide::Lower});
      else if (q[s.iq] >= s.upper - slack)
        on.push_back(StopReached{&s, StopSide::Upper});
    }
    return on;
  }

  void findJointsOnStops(
    const JointStops & stops, const Eigen::VectorXd & q, std::vector<Eigen::Index> & iv)
  {
    iv.clear();
    for (const JointStops::Stop & s : stops.stops())
      if (q[s.iq] <= s.lower || q[s.iq] >= s.upper)
        iv.push_back(s.iv);
  }

  StopHold::StopHold(const JointStops & stops, const LoopConstraints * loops)
  : stops_(stops)
  , loops_(loops)
  , dynamics_(&stops.model())
  {
    if (loops_ != nullptr)
      return;
    locked_ = stops_.model();
    locked_side_.assign(stops_.stops().size(), 0.);
    side_ = locked_side_;
    lock_mass_ = locked_side_;
  }

  void StopHold::start()
  {
    std::fill(locked_side_.begin(), locked_side_.end(), 0.);
    std::fill(side_.begin(), side_.end(), 0.);
    std::fill(lock_mass_.begin(), lock_mass_.end(), 0.);
    dynamics_ = &stops_.model();
    dynamics_version_ = 0;
  }

  void StopHold::useDynamicsModel(const pinocchio::Model & model, std::uint64_t version)
  {
    if (&model == dynamics_ && version == dynamics_version_)
      return;
    dynamics_ = &model;
    dynamics_version_ = version;
    // Lock again, from the new armature, at the next lockedModel().
    std::fill(locked_side_.begin(), locked_side_.end(), 0.);
  }

  double StopHold::restingSide(const JointStops::Stop & s, const Eigen::VectorXd & q, double v)
  {
    if (q[s.iq] <= s.lower && v <= 0.)
      return 1.;
    if (q[s.iq] >= s.upper && v >= 0.)
      return -1.;
    return 0.;
  }

  void StopHold::findResting(const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    // Joints on a stop and not moving off it: +1 on a lower stop, -1 on an upper one, the
    // direction in which its stop pushes.
    resting_.clear();
    for (const JointStops::Stop & s : stops_.stops())
    {
      const double side = restingSide(s, q, v[s.iv]);
      if (side != 0.)
        resting_.emplace_back(s.iv, side);
    }
  }

  namespace
  {
    // Resting joints (index in v, +1 on a lower stop / -1 on an upper one) whose acceleration in
    // a points into their stop.
    bool isIntoStop(const std::pair<int, double> & resting, const Eigen::VectorXd & a)
    {
      return resting.second * a[resting.first] < 0.;
    }

    // One pass of the hold's active set: a held joint whose stop would have to pull (reaction
    // against its side) is released, a free resting joint accelerated into its stop is held.
    // Returns whether anything changed.
    bool updateHeld(
      const std::vector<std::pair<int, double>> & resting,
      const Eigen::VectorXd & reactions,
      const Eigen::VectorXd & a,
      std::vector<bool> & held)
    {
      bool changed = false;
      for (std::size_t k = 0; k < resting.size(); ++k)
      {
        // The stop may only push (side * force >= 0).
        const bool release =
          held[k] && resting[k].second * reactions[static_cast<Eigen::Index>(k)] < 0.;
        const bool hold = !held[k] && isIntoStop(resting[k], a);
        if (release || hold)
        {
          held[k] = hold;
          changed = true;
        }
      }
      return changed;
    }
  } // namespace

  bool StopHold::hold(
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    const TimeScale * added)
  {
    findResting(q, v);
    if (std::none_of(resting_.begin(), resting_.end(), [&](const std::pair<int, double> & r) {
          return isIntoStop(r, data.ddq);
        }))
      return false;

    const pinocchio::Model & model = *dynamics_;
    free_acceleration_ = data.ddq;
    if (loops_ != nullptr)
      motions_ = computeLoopMotion(model, data, *loops_, q).basis;
    prebuilt::crba(model, data, q);
    mass_ = data.M.selfadjointView<Eigen::Upper>();
    if (added != nullptr && added->stiff_masses.size() > 0)
      mass_.noalias() +=
        added->stiff_momenta.transpose() * added->stiff_masses.asDiagonal() * added->stiff_momenta;
    force_.noalias() = mass_ * free_acceleration_;
    for (std::size_t k = 0; k < lock_mass_.size(); ++k)
      lock_mass_[k] = mass_(stops_.stops()[k].iv, stops_.stops()[k].iv);

    // Active set: hold the resting joints accelerated into their stop; then release a held
    // joint whose stop would have to pull, and hold a resting one now accelerated into its
    // stop, until neither happens (a bounded number of passes: the last one keeps its answer).
    held_.assign(resting_.size(), false);
    for (std::size_t k = 0; k < resting_.size(); ++k)
      held_[k] = isIntoStop(resting_[k], free_acceleration_);
    held_acceleration_ = free_acceleration_;
    const std::size_t passes = 2 * resting_.size() + 2;
    for (std::size_t pass = 0; pass < passes; ++pass)
    {
      if (loops_ != nullptr)
        solveHeldOnLoops(held_, free_acceleration_, held_acceleration_);
      else
        solveHeld(held_, held_acceleration_);
      if (!updateHeld(resting_, reactions_, held_acceleration_, held_))
        break;
    }
    data.ddq = held_acceleration_;
    return std::find(held_.begin(), held_.end(), true) != held_.end();
  }

  void StopHold::lock()
  {
    locked_.armature = dynamics_->armature;
    for (std::size_t k = 0; k < side_.size(); ++k)
      if (side_[k] != 0.)
        locked_.armature[stops_.stops()[k].iv] += kLockArmature * lock_mass_[k];
    locked_side_ = side_;
  }

  const pinocchio::Model * StopHold::lockedModel(
    const Eigen::VectorXd & q, const Eigen::VectorXd & v, const TimeScale * added)
  {
    if (loops_ != nullptr || (added != nullptr && added->stiff_masses.size() > 0))
      return nullptr;
    // Every joint resting on a stop and still (a held joint keeps v = 0; a joint that hits a
    // stop has its velocity into it removed).
    bool any = false;
    for (std::size_t k = 0; k < side_.size(); ++k)
    {
      const JointStops::Stop & s = stops_.stops()[k];
      side_[k] = v[s.iv] == 0. ? restingSide(s, q, 0.) : 0.;
      if (side_[k] != 0. && lock_mass_[k] <= 0.)
        return nullptr;
      any = any || side_[k] != 0.;
    }
    if (!any)
      return nullptr;
    if (side_ != locked_side_)
      lock();
    return &locked_;
  }

  bool StopHold::acceptLocked(
    pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    for (std::size_t k = 0; k < locked_side_.size(); ++k)
    {
      const JointStops::Stop & s = stops_.stops()[k];
      const double a = data.ddq[s.iv];
      // A locked joint still accelerates a little, into its stop while the stop pushes (its
      // armature takes the stop's force); a resting joint not locked must not move into its stop.
      const double side = locked_side_[k] != 0. ? -locked_side_[k] : restingSide(s, q, v[s.iv]);
      if (side * a < 0.)
        return false;
    }
    for (std::size_t k = 0; k < locked_side_.size(); ++k)
      if (locked_side_[k] != 0.)
        data.ddq[stops_.stops()[k].iv] = 0.;
    return true;
  }

  const pinocchio::Model * StopHold::unlockPulled(
    const pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v)
  {
    bool pulled = false, any = false;
    for (std::size_t k = 0; k < locked_side_.size(); ++k)
    {
      const JointStops::Stop & s = stops_.stops()[k];
      const double a = data.ddq[s.iv];
      side_[k] = locked_side_[k];
      if (locked_side_[k] != 0. && locked_side_[k] * a > 0.)
      {
        side_[k] = 0.;
        pulled = true;
      }
      else if (locked_side_[k] == 0. && restingSide(s, q, v[s.iv]) * a < 0.)
        return nullptr;
      any = any || side_[k] != 0.;
    }
    if (!pulled || !any)
      return nullptr;
    lock();
    return &locked_;
  }

  void StopHold::solveHeld(const std::vector<bool> & held, Eigen::VectorXd & a)
  {
    const Eigen::Index nv = force_.size();
    fixed_.assign(static_cast<std::size_t>(nv), false);
    for (std::size_t k = 0; k < resting_.size(); ++k)
      if (held[k])
        fixed_[static_cast<std::size_t>(resting_[k].first)] = true;
    free_.clear();
    for (Eigen::Index i = 0; i < nv; ++i)
      if (!fixed_[static_cast<std::size_t>(i)])
        free_.push_back(static_cast<int>(i));
    const Eigen::Index n = static_cast<Eigen::Index>(free_.size());
    mass_ff_.resize(n, n);
    force_f_.resize(n);
    for (Eigen::Index r = 0; r < n; ++r)
    {
      force_f_[r] = force_[free_[r]];
      for (Eigen::Index c = 0; c < n; ++c)
        mass_ff_(r, c) = mass_(free_[r], free_[c]);
    }
    a.setZero();
    if (n > 0)
    {
      llt_.compute(mass_ff_);
      llt_.solveInPlace(force_f_);
      for (Eigen::Index r = 0; r < n; ++r)
        a[free_[r]] = force_f_[r];
    }
    // The stop's force on a held joint is M a - f.
    reactions_.setZero(static_cast<Eigen::Index>(resting_.size()));
    for (std::size_t k = 0; k < resting_.size(); ++k)
      if (held[k])
      {
        const int i = resting_[k].first;
        reactions_[static_cast<Eigen::Index>(k)] = mass_.row(i).dot(a) - force_[i];
      }
  }

  void StopHold::solveHeldOnLoops(
    const std::vector<bool> & held, const Eigen::VectorXd & a_free, Eigen::VectorXd & a)
  {
    // Gauss's principle on the closed mechanism: a = a_free + N y, the held joints' rows
    // G = E N y = -E a_free, y of least N^T M N norm: y = Mr^-1 G^T mu with
    // (G Mr^-1 G^T) mu = -E a_free; mu are the stops' forces on the held joints.
    const Eigen::MatrixXd & N = motions_;
    std::vector<Eigen::Index> rows;
    for (std::size_t k = 0; k < resting_.size(); ++k)
      if (held[k])
        rows.push_back(resting_[k].first);
    const Eigen::Index h = static_cast<Eigen::Index>(rows.size());
    reactions_.setZero(static_cast<Eigen::Index>(resting_.size()));
    a = a_free;
    if (h == 0 || N.cols() == 0)
      return;
    const Eigen::MatrixXd reduced_mass = N.transpose() * mass_ * N;
    const Eigen::LLT<Eigen::MatrixXd> llt(reduced_mass);
    Eigen::MatrixXd G(h, N.cols());
    Eigen::VectorXd target(h);
    for (Eigen::Index r = 0; r < h; ++r)
    {
      G.row(r) = N.row(rows[static_cast<std::size_t>(r)]);
      target[r] = -a_free[rows[static_cast<std::size_t>(r)]];
    }
    const Eigen::MatrixXd MrG = llt.solve(G.transpose());
    // Held joints that the loops already tie together make the system singular: least norm.
    const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(G * MrG);
    const Eigen::VectorXd mu = cod.solve(target);
    a.noalias() += N * (MrG * mu);
    Eigen::Index r = 0;
    for (std::size_t k = 0; k < resting_.size(); ++k)
      if (held[k])
        reactions_[static_cast<Eigen::Index>(k)] = mu[r++];
  }

} // namespace pinsettle
