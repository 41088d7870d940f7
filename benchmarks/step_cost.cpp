//
// Cost of one kinetic-damping step against a bare pinocchio::aba + pinocchio::integrate step on
// the same model, in the same run: the loop's overhead as a ratio (median of repeats). Also the
// cost of the force elements: a scene without any (which must step as fast as the bare core),
// joint springs on every joint, and one point spring from the last body to the world.
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

  double settleStep(
    const pinocchio::Model & model,
    long steps,
    pinsettle::EnergyMeasure measure,
    const pinsettle::ForceModel * forces = nullptr)
  {
    pinsettle::Settings settings;
    settings.max_e = 0.; // never stops early: exactly `steps` steps
    settings.max_steps = steps;
    settings.energy = measure;
    pinsettle::Solver solver(model);
    const pinsettle::Result result = solver.solve(pinocchio::neutral(model), settings, forces);
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

  pinsettle::ForceElements none(model), joint_springs(model), point_spring(model);
  for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    if (model.nvs[j] == 1)
      joint_springs.addJointSpring(j, 10., 0.1, 0.);
  point_spring.addPointSpring(
    model.frames.size() - 1, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0.3, 0.2, 0.5), 100.);

  std::vector<double> bare, exact, simplified, empty, springs, point;
  for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
  {
    bare.push_back(bareStep(model, steps, 1e-3));
    exact.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact));
    simplified.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Simplified));
    empty.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &none));
    springs.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &joint_springs));
    point.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &point_spring));
  }
  const double b = median(bare);
  auto row = [&](const char * name, const std::vector<double> & t) {
    const double m = median(t);
    std::cout << name << " " << m * 1e9 << " ns/step  ratio " << m / b << "\n";
  };
  std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << steps
            << " steps, median of " << repeats << "\n"
            << "bare aba+integrate          " << b * 1e9 << " ns/step\n";
  row("pinsettle (exact)          ", exact);
  row("pinsettle (simplified)     ", simplified);
  row("scene without elements     ", empty);
  row("joint springs on all joints", springs);
  row("one point spring           ", point);
  return 0;
}
