//
// Cost of one kinetic-damping step against a bare pinocchio::aba + pinocchio::integrate step on
// the same model, in the same run: the loop's overhead as a ratio (median of repeats).
//
//   step_cost ROBOT.urdf [steps] [repeats]
//

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <vector>

namespace
{
  typedef std::chrono::steady_clock Clock;

  double median(std::vector<double> values)
  {
    std::sort(values.begin(), values.end());
    return values[values.size() / 2];
  }

  // The baseline: semi-implicit Euler on pinocchio::aba, nothing else.
  double bareStep(const pinocchio::Model & model, long steps, double dt)
  {
    pinocchio::Data data(model);
    Eigen::VectorXd q = pinocchio::neutral(model), q_next(model.nq);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv), dq(model.nv);
    const Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    const Clock::time_point start = Clock::now();
    for (long k = 0; k < steps; ++k)
    {
      pinocchio::aba(model, data, q, v, tau);
      v.noalias() += dt * data.ddq;
      dq.noalias() = dt * v;
      pinocchio::integrate(model, q, dq, q_next);
      q.swap(q_next);
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (!q.allFinite())
      std::cerr << "baseline diverged\n";
    return seconds / static_cast<double>(steps);
  }

  double settleStep(const pinocchio::Model & model, long steps, pinsettle::EnergyMeasure measure)
  {
    pinsettle::Settings settings;
    settings.max_e = 0.; // never stops early: exactly `steps` steps
    settings.max_steps = steps;
    settings.energy = measure;
    pinsettle::Solver solver(model);
    const pinsettle::Result result = solver.solve(pinocchio::neutral(model), settings);
    return result.wall_time / static_cast<double>(result.steps);
  }
} // namespace

int main(int argc, char ** argv)
{
  if (argc < 2)
  {
    std::cerr << "usage: " << argv[0] << " ROBOT.urdf [steps] [repeats]\n";
    return 2;
  }
  const pinocchio::Model model = pinsettle::buildModelFromUrdf(argv[1]);
  const long steps = argc > 2 ? std::atol(argv[2]) : 20000;
  const int repeats = argc > 3 ? std::atoi(argv[3]) : 11;

  std::vector<double> bare, exact, simplified;
  for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all three alike
  {
    bare.push_back(bareStep(model, steps, 1e-3));
    exact.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact));
    simplified.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Simplified));
  }
  const double b = median(bare), e = median(exact), s = median(simplified);
  std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << steps
            << " steps, median of " << repeats << "\n"
            << "bare aba+integrate  " << b * 1e9 << " ns/step\n"
            << "pinsettle (exact)   " << e * 1e9 << " ns/step  ratio " << e / b << "\n"
            << "pinsettle (simpl.)  " << s * 1e9 << " ns/step  ratio " << s / b << "\n";
  return 0;
}
