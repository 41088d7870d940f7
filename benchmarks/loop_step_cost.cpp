//
// Cost of one kinetic-damping step on a closed mechanism against a bare
// pinocchio::constraintDynamics + pinocchio::integrate step on the same model and loops, in the
// same run (median of interleaved repeats). The solver's step adds to that bare step the energy
// measures, the peak detection and the projections of q onto the loops and of v onto the
// motions they allow. For scale, also a bare pinocchio::aba + integrate step on the open tree
// (the loops cut).
//
// The start is the given configuration moved onto the loops (pinsettle::assembleLoops), at
// rest, under gravity alone; as in step_cost.cpp the solver runs with kt = 0.99 and max_e = 0
// (it damps at every peak but never stops) and the bare steps take a tenth of the solver's
// automatic step at the start. The bare constrained step uses the solver's constraint models
// (CONTACT_3D or CONTACT_6D, LOCAL_WORLD_ALIGNED) and its proximal settings (regularisation
// 1e-12 of the Delassus matrix's largest diagonal entry); it does not project, and holds the
// loops with Baumgarte's correction instead (Pinocchio's corrector gains), as a bare
// simulation would.
//
//   loop_step_cost ROBOT.urdf STEPS REPEATS --q0 Q1,Q2,... \
//     --loop FRAME_A,AX,AY,AZ,FRAME_B,BX,BY,BZ,point|frame [--loop ...] [--json]
//

#define PINOCCHIO_DISABLE_UNSUPPORTED_WARNINGS // constrained dynamics: Pinocchio 3's API

#include "bare-step.hpp"

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/cholesky.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace
{
  typedef pinocchio::RigidConstraintModel ConstraintModel;
  typedef pinocchio::RigidConstraintData ConstraintData;

  std::vector<std::string> split(const std::string & text)
  {
    std::vector<std::string> out;
    std::stringstream stream(text);
    for (std::string item; std::getline(stream, item, ',');)
      out.push_back(item);
    return out;
  }

  double number(const std::string & text, const std::string & what)
  {
    char * end = nullptr;
    const double x = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0')
      throw std::invalid_argument(what + ": expected a number, got '" + text + "'");
    return x;
  }

  // --loop FRAME_A,AX,AY,AZ,FRAME_B,BX,BY,BZ,KIND
  void addLoop(
    pinsettle::LoopConstraints & loops, const pinocchio::Model & model, const std::string & spec)
  {
    const std::vector<std::string> f = split(spec);
    if (f.size() != 9 || (f[8] != "point" && f[8] != "frame"))
      throw std::invalid_argument(
        "--loop: expected FRAME_A,AX,AY,AZ,FRAME_B,BX,BY,BZ,point|frame, got '" + spec + "'");
    for (const std::string & frame : {f[0], f[4]})
      if (!model.existFrame(frame))
        throw std::invalid_argument("--loop: no frame '" + frame + "' in the model");
    const Eigen::Vector3d a(number(f[1], "--loop"), number(f[2], "--loop"), number(f[3], "--loop"));
    const Eigen::Vector3d b(number(f[5], "--loop"), number(f[6], "--loop"), number(f[7], "--loop"));
    loops.addLoop(
      model.getFrameId(f[0]), a, model.getFrameId(f[4]), b,
      f[8] == "point" ? pinsettle::LoopKind::Point : pinsettle::LoopKind::Frame);
  }

  // The closed mechanism's bare step: semi-implicit Euler on pinocchio::constraintDynamics,
  // with the constraint models and proximal settings of LoopStepper (cpp/src/loops.cpp), which
  // keeps them private; a change there belongs here too.
  double bareLoopStep(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const Eigen::VectorXd & q0,
    long steps,
    double dt)
  {
    std::vector<ConstraintModel> models;
    for (const pinsettle::Loop & loop : loops.loops())
      models.push_back(ConstraintModel(
        loop.kind == pinsettle::LoopKind::Point ? pinocchio::CONTACT_3D : pinocchio::CONTACT_6D,
        model, loop.joint_a, loop.placement_a, loop.joint_b, loop.placement_b,
        pinocchio::LOCAL_WORLD_ALIGNED));
    // Without projections the bare step drifts off the loops, and unchecked drift ends in
    // non-finite numbers (which would time something else): Baumgarte's correction holds it,
    // critically damped at a tenth of the step's frequency (Kd dt = 0.2).
    const double omega = 0.1 / dt;
    for (ConstraintModel & cm : models)
      cm.baumgarte_corrector_parameters() =
        ConstraintModel::BaumgarteCorrectorParameters(omega * omega, 2 * omega);
    std::vector<ConstraintData> datas;
    for (const ConstraintModel & cm : models)
      datas.push_back(ConstraintData(cm));
    pinocchio::Data data(model);
    pinocchio::initConstraintDynamics(model, data, models, datas);
    const Eigen::MatrixXd J = pinsettle::computeLoopJacobian(model, data, loops, q0);
    pinocchio::computeMinverse(model, data, q0);
    const Eigen::MatrixXd Minv = data.Minv.selfadjointView<Eigen::Upper>();
    const double scale = (J * Minv * J.transpose()).diagonal().maxCoeff();
    pinocchio::ProximalSettings prox(1e-14, std::max(1e-12 * scale, 1e-300), 20);

    const Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    return bench::timeBareStep(
      model, data, q0, steps, dt,
      [&](const Eigen::VectorXd & q, const Eigen::VectorXd & v) {
        pinocchio::constraintDynamics(model, data, q, v, tau, models, datas, prox);
      },
      "bare constrained step");
  }

  long settled_steps = 0;
  double constraint_error = 0.;

  double settleStep(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const Eigen::VectorXd & q0,
    long steps,
    pinsettle::EnergyMeasure measure)
  {
    pinsettle::Settings settings;
    settings.max_e = 0.;              // never stops early: exactly `steps` steps
    settings.newton_takeover = false; // nor Newton at a damping event
    settings.kt = 0.99;               // stays clear of subnormal velocities (see step_cost.cpp)
    settings.max_steps = steps;
    settings.energy = measure;
    pinsettle::Solver solver(model, &loops);
    const pinsettle::Result result = solver.solve(q0, settings);
    settled_steps = static_cast<long>(result.info.steps);
    constraint_error = result.constraint_error;
    return result.info.wall_time / static_cast<double>(result.info.steps);
  }

  struct Options
  {
    std::vector<std::string> args, loop_specs; // args: ROBOT.urdf STEPS REPEATS
    std::string q_spec;
    bool json = false;
  };

  Options parseOptions(int argc, char ** argv)
  {
    Options options;
    for (int k = 1; k < argc; ++k)
    {
      const std::string arg = argv[k];
      if (arg == "--json")
        options.json = true;
      else if (arg == "--loop" && k + 1 < argc)
        options.loop_specs.push_back(argv[++k]);
      else if (arg == "--q0" && k + 1 < argc)
        options.q_spec = argv[++k];
      else
        options.args.push_back(arg);
    }
    return options;
  }

  bool complete(const Options & options)
  {
    return options.args.size() == 3 && !options.loop_specs.empty() && !options.q_spec.empty();
  }

  // --q0 Q1,Q2,...: model.nq numbers.
  Eigen::VectorXd readStart(const pinocchio::Model & model, const std::string & q_spec)
  {
    const std::vector<std::string> entries = split(q_spec);
    if (static_cast<int>(entries.size()) != model.nq)
      throw std::invalid_argument(
        "--q0: expected " + std::to_string(model.nq) + " numbers (model.nq), got "
        + std::to_string(entries.size()));
    Eigen::VectorXd q0(model.nq);
    for (int i = 0; i < model.nq; ++i)
      q0[i] = number(entries[static_cast<std::size_t>(i)], "--q0");
    return q0;
  }

  // Per-step times (s) of the four steps, one entry per repeat; their names are the JSON's.
  struct Times
  {
    std::vector<double> bare_tree, bare, exact, simplified;
  };

  Times timeSteps(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const Eigen::VectorXd & q0,
    long steps,
    double dt,
    int repeats)
  {
    Times t;
    for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
    {
      t.bare_tree.push_back(bench::timeBareAbaStep(model, q0, steps, dt, "bare tree step"));
      t.bare.push_back(bareLoopStep(model, loops, q0, steps, dt));
      t.exact.push_back(settleStep(model, loops, q0, steps, pinsettle::EnergyMeasure::Exact));
      t.simplified.push_back(
        settleStep(model, loops, q0, steps, pinsettle::EnergyMeasure::Simplified));
    }
    return t;
  }

  // The runs' size, the bare steps' fixed step (s) and how far the start was moved onto the
  // loops.
  struct RunSetup
  {
    long steps;
    int repeats;
    double dt, moved;
  };

  // Per-step times of every repeat (ns), for benchmarks/report.py.
  void printJson(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const RunSetup & setup,
    const Times & t)
  {
    std::cout << "{\"nq\": " << model.nq << ", \"nv\": " << model.nv
              << ", \"rows\": " << loops.rows() << ", \"steps\": " << setup.steps
              << ", \"settled_steps\": " << settled_steps << ", \"dt\": " << setup.dt
              << ", \"assembly_distance\": " << setup.moved
              << ", \"constraint_error\": " << constraint_error
              << ", \"ns_per_step\": {\"bare_tree\": " << bench::jsonList(t.bare_tree)
              << ", \"bare\": " << bench::jsonList(t.bare)
              << ", \"exact\": " << bench::jsonList(t.exact)
              << ", \"simplified\": " << bench::jsonList(t.simplified) << "}}\n";
  }

  // The medians against the bare constrained step's.
  void printTable(
    const pinocchio::Model & model,
    const pinsettle::LoopConstraints & loops,
    const RunSetup & setup,
    const Times & t)
  {
    const double b = bench::median(t.bare);
    auto row = [&](const char * name, const std::vector<double> & times) {
      const double m = bench::median(times);
      std::cout << name << " " << m * 1e9 << " ns/step  ratio " << m / b << "\n";
    };
    std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << loops.rows()
              << " loop equations, " << setup.steps << " steps (the last solver run took "
              << settled_steps << ", constraint error " << constraint_error << "), dt " << setup.dt
              << " s, median of " << setup.repeats << "\n"
              << "bare constraintDynamics+integrate " << b * 1e9 << " ns/step\n";
    row("bare aba+integrate (open tree)   ", t.bare_tree);
    row("pinsettle (exact)                ", t.exact);
    row("pinsettle (simplified)           ", t.simplified);
  }

  int run(int argc, char ** argv)
  {
    const Options options = parseOptions(argc, argv);
    if (!complete(options))
    {
      std::cerr << "usage: " << argv[0]
                << " ROBOT.urdf STEPS REPEATS --q0 Q1,Q2,... "
                   "--loop FRAME_A,AX,AY,AZ,FRAME_B,BX,BY,BZ,point|frame [--loop ...] [--json]\n";
      return 2;
    }
    const pinocchio::Model model = pinsettle::buildModelFromUrdf(options.args[0]);
    RunSetup setup{std::atol(options.args[1].c_str()), std::atoi(options.args[2].c_str()), 0., 0.};
    if (setup.steps <= 0 || setup.repeats <= 0)
      throw std::invalid_argument("STEPS and REPEATS must be positive integers");
    pinsettle::LoopConstraints loops(model);
    for (const std::string & spec : options.loop_specs)
      addLoop(loops, model, spec);
    Eigen::VectorXd q0 = readStart(model, options.q_spec);

    pinocchio::Data data(model);
    setup.moved = pinsettle::assembleLoops(model, data, loops, q0);
    setup.dt = 0.1 * pinsettle::effectiveDtSafety(pinsettle::Settings())
               * pinsettle::computeTimeScale(model, data, loops, q0).critical_step;
    const Times times = timeSteps(model, loops, q0, setup.steps, setup.dt, setup.repeats);
    if (options.json)
      printJson(model, loops, setup, times);
    else
      printTable(model, loops, setup, times);
    return 0;
  }
} // namespace

int main(int argc, char ** argv)
{
  try
  {
    return run(argc, argv);
  }
  catch (const std::exception & e)
  {
    std::cerr << argv[0] << ": " << e.what() << "\n";
    return 2;
  }
}
