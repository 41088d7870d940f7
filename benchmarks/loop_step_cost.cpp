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
    settled_steps = static_cast<long>(result.steps);
    constraint_error = result.constraint_error;
    return result.wall_time / static_cast<double>(result.steps);
  }

  int run(int argc, char ** argv)
  {
    std::vector<std::string> args, loop_specs;
    std::string q_spec;
    bool json = false;
    for (int k = 1; k < argc; ++k)
    {
      const std::string arg = argv[k];
      if (arg == "--json")
        json = true;
      else if ((arg == "--loop" || arg == "--q0") && k + 1 < argc)
        (arg == "--loop" ? loop_specs.push_back(argv[++k]) : void(q_spec = argv[++k]));
      else
        args.push_back(arg);
    }
    if (args.size() != 3 || loop_specs.empty() || q_spec.empty())
    {
      std::cerr << "usage: " << argv[0]
                << " ROBOT.urdf STEPS REPEATS --q0 Q1,Q2,... "
                   "--loop FRAME_A,AX,AY,AZ,FRAME_B,BX,BY,BZ,point|frame [--loop ...] [--json]\n";
      return 2;
    }
    const pinocchio::Model model = pinsettle::buildModelFromUrdf(args[0]);
    const long steps = std::atol(args[1].c_str());
    const int repeats = std::atoi(args[2].c_str());
    if (steps <= 0 || repeats <= 0)
      throw std::invalid_argument("STEPS and REPEATS must be positive integers");
    pinsettle::LoopConstraints loops(model);
    for (const std::string & spec : loop_specs)
      addLoop(loops, model, spec);
    const std::vector<std::string> entries = split(q_spec);
    if (static_cast<int>(entries.size()) != model.nq)
      throw std::invalid_argument(
        "--q0: expected " + std::to_string(model.nq) + " numbers (model.nq), got "
        + std::to_string(entries.size()));
    Eigen::VectorXd q0(model.nq);
    for (int i = 0; i < model.nq; ++i)
      q0[i] = number(entries[static_cast<std::size_t>(i)], "--q0");

    pinocchio::Data data(model);
    const double moved = pinsettle::assembleLoops(model, data, loops, q0);
    const double dt = 0.1 * pinsettle::effectiveDtSafety(pinsettle::Settings())
                      * pinsettle::computeTimeScale(model, data, loops, q0).critical_step;

    std::vector<double> tree, bare, exact, simplified;
    for (int r = 0; r < repeats; ++r) // interleaved, so that machine noise hits all alike
    {
      tree.push_back(bench::timeBareAbaStep(model, q0, steps, dt, "bare tree step"));
      bare.push_back(bareLoopStep(model, loops, q0, steps, dt));
      exact.push_back(settleStep(model, loops, q0, steps, pinsettle::EnergyMeasure::Exact));
      simplified.push_back(
        settleStep(model, loops, q0, steps, pinsettle::EnergyMeasure::Simplified));
    }
    if (json) // per-step times of every repeat (ns), for benchmarks/report.py
    {
      std::cout << "{\"nq\": " << model.nq << ", \"nv\": " << model.nv
                << ", \"rows\": " << loops.rows() << ", \"steps\": " << steps
                << ", \"settled_steps\": " << settled_steps << ", \"dt\": " << dt
                << ", \"assembly_distance\": " << moved
                << ", \"constraint_error\": " << constraint_error
                << ", \"ns_per_step\": {\"bare_tree\": " << bench::jsonList(tree)
                << ", \"bare\": " << bench::jsonList(bare)
                << ", \"exact\": " << bench::jsonList(exact)
                << ", \"simplified\": " << bench::jsonList(simplified) << "}}\n";
      return 0;
    }
    const double b = bench::median(bare);
    auto row = [&](const char * name, const std::vector<double> & t) {
      const double m = bench::median(t);
      std::cout << name << " " << m * 1e9 << " ns/step  ratio " << m / b << "\n";
    };
    std::cout << "model nq=" << model.nq << " nv=" << model.nv << ", " << loops.rows()
              << " loop equations, " << steps << " steps (the last solver run took "
              << settled_steps << ", constraint error " << constraint_error << "), dt " << dt
              << " s, median of " << repeats << "\n"
              << "bare constraintDynamics+integrate " << b * 1e9 << " ns/step\n";
    row("bare aba+integrate (open tree)   ", tree);
    row("pinsettle (exact)                ", exact);
    row("pinsettle (simplified)           ", simplified);
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
