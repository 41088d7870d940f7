//
// Cost of one kinetic-damping step against a bare pinocchio::aba + pinocchio::integrate step on
// the same model, in the same run: the loop's overhead as a ratio (median of repeats). Also the
// cost of the force elements: a scene without any (which must step as fast as the bare core),
// joint springs on every joint, and one point spring from the last body to the world.
//
// Every run starts at rest 0.3 rad (or m) away from the neutral configuration in every degree of
// freedom, so that the mechanism moves (at its neutral pose a hanging chain is at rest, and the
// solver would stop after one stopping window). The solver runs with kt = 0.99 and max_e = 0:
// it damps at every energy peak as usual but never stops, and after `steps` steps its energy
// is still far above the subnormal range (with kt = 0.5 and thousands of peaks the velocity
// underflows to subnormal numbers, whose arithmetic is many times slower: a cost no real solve,
// which stops long before, pays). The bare step takes a tenth of the solver's automatic step at
// the start: without the solver's bound on the turn per step, a fixed step that large blows up
// on a swinging arm, and non-finite values would time something else. ABA costs the same
// whatever the step.
//
//   step_cost ROBOT.urdf [steps] [repeats] [--json]
//

#include "bare-step.hpp"

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>

#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <vector>

namespace
{
  // The start of every run: at rest, 0.3 rad (or m) from neutral in every degree of freedom.
  Eigen::VectorXd start(const pinocchio::Model & model)
  {
    return pinocchio::integrate(
      model, pinocchio::neutral(model), Eigen::VectorXd::Constant(model.nv, 0.3));
  }

  // Steps the last settle run took (max_e = 0 never stops a moving mechanism early).
  long settled_steps = 0;

  double settleStep(
    const pinocchio::Model & model,
    long steps,
    pinsettle::EnergyMeasure measure,
    const pinsettle::ForceModel * forces = nullptr)
  {
    pinsettle::Settings settings;
    settings.max_e = 0.; // never stops early: exactly `steps` steps
    settings.kt = 0.99;  // stays clear of subnormal velocities (see the top of the file)
    settings.max_steps = steps;
    settings.energy = measure;
    pinsettle::Solver solver(model);
    const pinsettle::Result result = solver.solve(start(model), settings, forces);
    settled_steps = static_cast<long>(result.steps);
    return result.wall_time / static_cast<double>(result.steps);
  }
} // namespace

int main(int argc, char ** argv)
{
  std::vector<std::string> args;
  bool json = false;
  for (int k = 1; k < argc; ++k)
    if (std::strcmp(argv[k], "--json") == 0)
      json = true;
    else
      args.push_back(argv[k]);
  if (args.empty())
  {
    std::cerr << "usage: " << argv[0] << " ROBOT.urdf [steps] [repeats] [--json]\n";
    return 2;
  }
  const pinocchio::Model model = pinsettle::buildModelFromUrdf(args[0]);
  const long steps = args.size() > 1 ? std::atol(args[1].c_str()) : 20000;
  const int repeats = args.size() > 2 ? std::atoi(args[2].c_str()) : 11;
  pinocchio::Data data(model);
  const double dt = 0.1 * pinsettle::Settings().dt_safety
                    * pinsettle::computeTimeScale(model, data, start(model)).critical_step;

  pinsettle::ForceElements none(model), joint_springs(model), point_spring(model);
  for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    if (model.nvs[j] == 1)
      joint_springs.addJointSpring(j, 10., 0.1, 0.);
  point_spring.addPointSpring(
    model.frames.size() - 1, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0.3, 0.2, 0.5), 100.);

  std::vector<double> bare, exact, simplified, empty, springs, point;
  for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
  {
    bare.push_back(bench::timeBareAbaStep(model, start(model), steps, dt, "baseline"));
    exact.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact));
    simplified.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Simplified));
    empty.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &none));
    springs.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &joint_springs));
    point.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &point_spring));
  }
  const double b = bench::median(bare);
  if (json) // per-step times of every repeat (s), for benchmarks/report.py
  {
    std::cout << "{\"nq\": " << model.nq << ", \"nv\": " << model.nv << ", \"steps\": " << steps
              << ", \"settled_steps\": " << settled_steps << ", \"dt\": " << dt
              << ", \"ns_per_step\": {\"bare\": " << bench::jsonList(bare)
              << ", \"exact\": " << bench::jsonList(exact)
              << ", \"simplified\": " << bench::jsonList(simplified)
              << ", \"no_elements\": " << bench::jsonList(empty)
              << ", \"joint_springs\": " << bench::jsonList(springs)
              << ", \"point_spring\": " << bench::jsonList(point) << "}}\n";
    return 0;
  }
  auto row = [&](const char * name, const std::vector<double> & t) {
    const double m = bench::median(t);
    std::cout << name << " " << m * 1e9 << " ns/step  ratio " << m / b << "\n";
  };
  std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << steps
            << " steps (the last solver run took " << settled_steps << "), dt " << dt
            << " s, median of " << repeats << "\n"
            << "bare aba+integrate          " << b * 1e9 << " ns/step\n";
  row("pinsettle (exact)          ", exact);
  row("pinsettle (simplified)     ", simplified);
  row("scene without elements     ", empty);
  row("joint springs on all joints", springs);
  row("one point spring           ", point);
  return 0;
}
