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
#include <functional>
#include <iostream>
#include <stdexcept>
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
    settled_steps = static_cast<long>(result.info.steps);
    if (stops != nullptr)
      stop_contacts = static_cast<long>(result.stop_contacts.size());
    return result.info.wall_time / static_cast<double>(result.info.steps);
  }

  struct Options
  {
    std::vector<std::string> args; // ROBOT.urdf [steps] [repeats]
    bool json = false;
    std::string only; // the rows to time, as ",bare,exact,"; empty: every row

    bool times(const std::string & row) const
    {
      return only.empty() || only.find("," + row + ",") != std::string::npos;
    }
  };

  Options parseOptions(int argc, char ** argv)
  {
    Options options;
    for (int k = 1; k < argc; ++k)
      if (std::strcmp(argv[k], "--json") == 0)
        options.json = true;
      else if (std::strcmp(argv[k], "--only") == 0 && k + 1 < argc)
        options.only = "," + std::string(argv[++k]) + ",";
      else
        options.args.push_back(argv[k]);
    return options;
  }

  // The bare steps' fixed step: a tenth of the solver's automatic step at the start, halved
  // until the bare run stays finite.
  double bareStepSize(const pinocchio::Model & model, long steps)
  {
    pinocchio::Data data(model);
    return finiteBareStep(
      model, steps,
      0.1 * pinsettle::effectiveDtSafety(pinsettle::Settings())
        * pinsettle::computeTimeScale(model, data, start(model)).critical_step);
  }

  // The force elements and stops the rows other than bare and exact add to the model.
  struct Additions
  {
    explicit Additions(const pinocchio::Model & model)
    : none(model)
    , joint_springs(model)
    , point_spring(model)
    , model_stops(model)
    , stops(model_stops.empty() ? nullptr : &model_stops)
    {
      for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
        if (model.nvs[j] == 1)
          joint_springs.addJointSpring(j, 10., 0.1, 0.);
      point_spring.addPointSpring(
        model.frames.size() - 1, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(0.3, 0.2, 0.5), 100.);
    }

    pinsettle::ForceElements none, joint_springs, point_spring;
    // The model's position limits as stops; none (a model without finite limits): nullptr.
    const pinsettle::JointStops model_stops;
    const pinsettle::JointStops * stops;
  };

  // A row of the table and a key of the JSON: what it times, and its time per step (s) in each
  // repeat.
  struct Row
  {
    const char * name; // as --only and the JSON name it
    const char * label;
    std::function<double()> time;
    std::vector<double> times;
  };

  std::vector<Row> makeRows(
    const pinocchio::Model & model, long steps, double dt, const Additions & with)
  {
    const pinsettle::EnergyMeasure exact = pinsettle::EnergyMeasure::Exact;
    return {
      {"bare", "bare aba+integrate         ",
       [&model, steps, dt] {
         return bench::timeBareAbaStep(model, start(model), steps, dt, "baseline");
       }},
      {"exact", "pinsettle (exact)          ",
       [&model, steps, exact] { return settleStep(model, steps, exact); }},
      {"simplified", "pinsettle (simplified)     ",
       [&model, steps] { return settleStep(model, steps, pinsettle::EnergyMeasure::Simplified); }},
      {"no_elements", "scene without elements     ",
       [&model, steps, exact, &with] { return settleStep(model, steps, exact, &with.none); }},
      {"joint_springs", "joint springs on all joints",
       [&model, steps, exact, &with] {
         return settleStep(model, steps, exact, &with.joint_springs);
       }},
      {"point_spring", "one point spring           ",
       [&model, steps, exact, &with] {
         return settleStep(model, steps, exact, &with.point_spring);
       }},
      {"stops", "joint stops of the model   ",
       [&model, steps, exact, &with] {
         return settleStep(model, steps, exact, nullptr, with.stops);
       }},
    };
  }

  const std::vector<double> & timesOf(const std::vector<Row> & rows, const std::string & name)
  {
    for (const Row & row : rows)
      if (name == row.name)
        return row.times;
    throw std::logic_error("no row " + name);
  }

  // Per-step times of every repeat (s), for benchmarks/report.py.
  void printJson(
    const pinocchio::Model & model,
    long steps,
    double dt,
    const Additions & with,
    const std::vector<Row> & rows)
  {
    std::cout << "{\"nq\": " << model.nq << ", \"nv\": " << model.nv << ", \"steps\": " << steps
              << ", \"settled_steps\": " << settled_steps << ", \"dt\": " << dt
              << ", \"stop_count\": " << with.model_stops.stops().size()
              << ", \"stop_contacts\": " << stop_contacts << ", \"ns_per_step\": {";
    for (std::size_t k = 0; k < rows.size(); ++k)
      std::cout << (k ? ", " : "") << "\"" << rows[k].name
                << "\": " << bench::jsonList(rows[k].times);
    std::cout << "}}\n";
  }

  // The medians against the bare step's.
  int printTable(
    const pinocchio::Model & model,
    long steps,
    int repeats,
    double dt,
    const Additions & with,
    const std::vector<Row> & rows)
  {
    const std::vector<double> &bare = timesOf(rows, "bare"), &exact = timesOf(rows, "exact"),
                              &stopped = timesOf(rows, "stops");
    if (bare.empty() || exact.empty())
    {
      std::cerr << "the table needs the bare and exact rows (or use --json)\n";
      return 2;
    }
    const double b = bench::median(bare);
    std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << steps
              << " steps (the last solver run took " << settled_steps << "), dt " << dt
              << " s, median of " << repeats << "\n"
              << rows.front().label << " " << b * 1e9 << " ns/step\n";
    for (const Row & row : rows)
    {
      if (row.times.empty() || std::strcmp(row.name, "bare") == 0) // bare: the line above
        continue;
      const double m = bench::median(row.times);
      std::cout << row.label << " " << m * 1e9 << " ns/step  ratio " << m / b << "\n";
    }
    if (!stopped.empty())
      std::cout << "stops / no stops " << bench::median(stopped) / bench::median(exact) << " ("
                << with.model_stops.stops().size() << " stops, " << stop_contacts
                << " joints on a stop at the end)\n";
    return 0;
  }
} // namespace

int main(int argc, char ** argv)
{
  const Options options = parseOptions(argc, argv);
  if (options.args.empty())
  {
    std::cerr << "usage: " << argv[0] << " ROBOT.urdf [steps] [repeats] [--json] [--only ROWS]\n";
    return 2;
  }
  const std::vector<std::string> & args = options.args;
  const pinocchio::Model model = pinsettle::buildModelFromUrdf(args[0]);
  const long steps = args.size() > 1 ? std::atol(args[1].c_str()) : 20000;
  const int repeats = args.size() > 2 ? std::atoi(args[2].c_str()) : 11;
  const double dt = bareStepSize(model, steps);
  const Additions with(model);
  std::vector<Row> rows = makeRows(model, steps, dt, with);
  for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
    for (Row & row : rows)
      if (options.times(row.name))
        row.times.push_back(row.time());
  if (options.json)
  {
    printJson(model, steps, dt, with, rows);
    return 0;
  }
  return printTable(model, steps, repeats, dt, with, rows);
}
