//
// Cost of one kinetic-damping step against a bare pinocchio::aba + pinocchio::integrate step on
// the same model, in the same run: the loop's overhead as a ratio (median of repeats). Also the
// cost of the force elements: a scene without any (which must step as fast as the bare core),
// joint springs on every joint, and one point spring from the last body to the world. And the
// cost of joint stops: the solver with the model's position limits as stops (JointStops) against
// the same solver without them, on the same start (a model without any finite limit has no stop:
// then both are the same run).
//
// Every run starts at rest 0.3 rad (or m) away from the neutral configuration in every degree of
// freedom, so that the mechanism moves (at its neutral pose a hanging chain is at rest, and the
// solver would stop after one stopping window). The solver runs with kt = 0.99 and max_e = 0:
// it damps at every energy peak as usual but never stops, and after `steps` steps its energy
// is still far above the subnormal range (with kt = 0.5 and thousands of peaks the velocity
// underflows to subnormal numbers, whose arithmetic is many times slower: a cost no real solve,
// which stops long before, pays). The bare step takes a tenth of the solver's automatic step at
// the start: without the solver's bound on the turn per step, a fixed step that large blows up
// on a swinging arm, and non-finite values would time something else (halved until the run stays
// finite: the Panda's light fingers need it). ABA costs the same whatever the step.
//
//   step_cost ROBOT.urdf [steps] [repeats] [--json] [--only bare,exact]
//
// --only times those rows alone (bare, exact, simplified, no_elements, joint_springs,
// point_spring, stops); the others are empty lists (the chain-scaling runs of long chains).
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

  // The largest of dt, dt / 2, dt / 4, ... whose bare run of `steps` steps stays finite (a light
  // finger on the Panda blows up at a tenth of the solver's first step; a run gone non-finite
  // would time something else).
  double finiteBareStep(const pinocchio::Model & model, long steps, double dt)
  {
    pinocchio::Data data(model);
    const Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    for (int halvings = 0; halvings < 30; ++halvings, dt *= 0.5)
    {
      Eigen::VectorXd q = start(model), v = Eigen::VectorXd::Zero(model.nv);
      for (long k = 0; k < steps && q.allFinite() && v.allFinite(); ++k)
      {
        v += dt * pinsettle::prebuilt::aba(model, data, q, v, tau);
        q = pinocchio::integrate(model, q, dt * v);
      }
      if (q.allFinite() && v.allFinite())
        return dt;
    }
    return dt;
  }

  // Steps the last settle run took (max_e = 0 never stops a moving mechanism early), and the
  // joints resting on a stop at the end of the last run with stops.
  long settled_steps = 0;
  long stop_contacts = 0;

  double settleStep(
    const pinocchio::Model & model,
    long steps,
    pinsettle::EnergyMeasure measure,
    const pinsettle::ForceModel * forces = nullptr,
    const pinsettle::JointStops * stops = nullptr)
  {
    pinsettle::Settings settings;
    settings.max_e = 0.;              // never stops early: exactly `steps` steps
    settings.newton_takeover = false; // nor Newton at a damping event
    settings.kt = 0.99; // stays clear of subnormal velocities (see the top of the file)
    settings.max_steps = steps;
    settings.energy = measure;
    pinsettle::Solver solver(model, nullptr, stops);
    const pinsettle::Result result = solver.solve(start(model), settings, forces);
    settled_steps = static_cast<long>(result.steps);
    if (stops != nullptr)
      stop_contacts = static_cast<long>(result.stop_contacts.size());
    return result.wall_time / static_cast<double>(result.steps);
  }
} // namespace

int main(int argc, char ** argv)
{
  std::vector<std::string> args;
  bool json = false;
  std::string only; // comma-separated rows to time; empty: every row
  for (int k = 1; k < argc; ++k)
    if (std::strcmp(argv[k], "--json") == 0)
      json = true;
    else if (std::strcmp(argv[k], "--only") == 0 && k + 1 < argc)
      only = "," + std::string(argv[++k]) + ",";
    else
      args.push_back(argv[k]);
  auto timed = [&](const char * row) {
    return only.empty() || only.find("," + std::string(row) + ",") != std::string::npos;
  };
  if (args.empty())
  {
    std::cerr << "usage: " << argv[0] << " ROBOT.urdf [steps] [repeats] [--json] [--only ROWS]\n";
    return 2;
  }
  const pinocchio::Model model = pinsettle::buildModelFromUrdf(args[0]);
  const long steps = args.size() > 1 ? std::atol(args[1].c_str()) : 20000;
  const int repeats = args.size() > 2 ? std::atoi(args[2].c_str()) : 11;
  pinocchio::Data data(model);
  const double dt = finiteBareStep(
    model, steps,
    0.1 * pinsettle::effectiveDtSafety(pinsettle::Settings())
      * pinsettle::computeTimeScale(model, data, start(model)).critical_step);

  pinsettle::ForceElements none(model), joint_springs(model), point_spring(model);
  for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
    if (model.nvs[j] == 1)
      joint_springs.addJointSpring(j, 10., 0.1, 0.);
  point_spring.addPointSpring(
    model.frames.size() - 1, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0.3, 0.2, 0.5), 100.);

  // The model's position limits as stops; none (a model without finite limits): nullptr.
  const pinsettle::JointStops model_stops(model);
  const pinsettle::JointStops * stops = model_stops.empty() ? nullptr : &model_stops;

  std::vector<double> bare, exact, simplified, empty, springs, point, stopped;
  for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
  {
    if (timed("bare"))
      bare.push_back(bench::timeBareAbaStep(model, start(model), steps, dt, "baseline"));
    if (timed("exact"))
      exact.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact));
    if (timed("simplified"))
      simplified.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Simplified));
    if (timed("no_elements"))
      empty.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &none));
    if (timed("joint_springs"))
      springs.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &joint_springs));
    if (timed("point_spring"))
      point.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, &point_spring));
    if (timed("stops"))
      stopped.push_back(settleStep(model, steps, pinsettle::EnergyMeasure::Exact, nullptr, stops));
  }
  if (json) // per-step times of every repeat (s), for benchmarks/report.py
  {
    std::cout << "{\"nq\": " << model.nq << ", \"nv\": " << model.nv << ", \"steps\": " << steps
              << ", \"settled_steps\": " << settled_steps << ", \"dt\": " << dt
              << ", \"stop_count\": " << model_stops.stops().size()
              << ", \"stop_contacts\": " << stop_contacts
              << ", \"ns_per_step\": {\"bare\": " << bench::jsonList(bare)
              << ", \"exact\": " << bench::jsonList(exact)
              << ", \"simplified\": " << bench::jsonList(simplified)
              << ", \"no_elements\": " << bench::jsonList(empty)
              << ", \"joint_springs\": " << bench::jsonList(springs)
              << ", \"point_spring\": " << bench::jsonList(point)
              << ", \"stops\": " << bench::jsonList(stopped) << "}}\n";
    return 0;
  }
  if (bare.empty() || exact.empty())
  {
    std::cerr << "the table needs the bare and exact rows (or use --json)\n";
    return 2;
  }
  const double b = bench::median(bare);
  auto row = [&](const char * name, const std::vector<double> & t) {
    if (t.empty())
      return;
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
  row("joint stops of the model   ", stopped);
  if (!stopped.empty())
    std::cout << "stops / no stops " << bench::median(stopped) / bench::median(exact) << " ("
              << model_stops.stops().size() << " stops, " << stop_contacts
              << " joints on a stop at the end)\n";
  return 0;
}
