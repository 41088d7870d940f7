//
// What step_cost.cpp and loop_step_cost.cpp share: the median of repeats, the timed bare step
// (semi-implicit Euler on a Pinocchio dynamics call, nothing else) and the per-step times as
// JSON.
//

#ifndef __pinsettle_benchmarks_bare_step_hpp__
#define __pinsettle_benchmarks_bare_step_hpp__

#include <pinsettle/prebuilt.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/multibody/data.hpp>
#include <pinocchio/multibody/model.hpp>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <string>
#include <vector>

namespace bench
{
  inline double median(std::vector<double> values)
  {
    std::sort(values.begin(), values.end());
    return values[values.size() / 2];
  }

  ///
  /// \brief Seconds per step of `steps` semi-implicit Euler steps from q0 at rest, with fixed
  /// step dt (s): `dynamics(q, v)` leaves the acceleration in data.ddq (dim model.nv).
  /// Reports on stderr when the run ends non-finite (its times would measure something else).
  ///
  template<typename Dynamics>
  double timeBareStep(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q0,
    long steps,
    double dt,
    Dynamics dynamics,
    const char * what)
  {
    Eigen::VectorXd q = q0, q_next(model.nq);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv), dq(model.nv);
    const std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
    for (long k = 0; k < steps; ++k)
    {
      dynamics(q, v);
      v.noalias() += dt * data.ddq;
      dq.noalias() = dt * v;
      pinocchio::integrate(model, q, dq, q_next);
      q.swap(q_next);
    }
    const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!q.allFinite())
      std::cerr << what << " diverged\n";
    return seconds / static_cast<double>(steps);
  }

  /// \brief The tree's bare step: timeBareStep on pinocchio::aba with zero joint efforts, in
  /// the world convention as the solver's step (Pinocchio's faster one), through its prebuilt
  /// instantiation as the solver calls it (as fast as one compiled here: 2294 against 2302 ns
  /// per call on the UR5, medians of 15 interleaved repeats).
  inline double timeBareAbaStep(
    const pinocchio::Model & model,
    const Eigen::VectorXd & q0,
    long steps,
    double dt,
    const char * what)
  {
    pinocchio::Data data(model);
    const Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    return timeBareStep(
      model, data, q0, steps, dt,
      [&](const Eigen::VectorXd & q, const Eigen::VectorXd & v) {
        pinsettle::prebuilt::aba(model, data, q, v, tau, pinocchio::Convention::WORLD);
      },
      what);
  }

  /// \brief Per-step times (s) as a JSON list in ns.
  inline std::string jsonList(const std::vector<double> & t)
  {
    std::string out = "[";
    for (std::size_t k = 0; k < t.size(); ++k)
      out += (k ? ", " : "") + std::to_string(t[k] * 1e9);
    return out + "]";
  }
} // namespace bench

#endif // ifndef __pinsettle_benchmarks_bare_step_hpp__
