//
// Where a kinetic-damping solve spends its time (benchmarks/report.py, the overhead split): the
// solver's set-up, its step estimates, its stability assessments and the Newton polish, against
// the whole solve and against the bare steps (pinocchio::aba + integrate) it takes.
//
// The solver's library calls pinsettle::computeTimeScale (from StepController: the step
// estimates), pinsettle::assessStability (from the solver: the rest checks, the final verdict,
// the polish) and pinsettle::computeStiffnessMatrix (the polish) across translation units. This
// program is linked with the linker's --wrap for those symbols (benchmarks/CMakeLists.txt), so
// each call goes through a wrapper here that times it and calls the real function: the solver's
// code is unchanged and nothing is sampled. Nested calls (an assessment made inside another
// part) count once, in the outermost part.
//
// - set-up: from the call of Solver::solve to the end of the first step estimate (the settings
//   and model checks, the mass-matrix check, the first estimate);
// - step estimates: every later estimate;
// - stability assessments: every assessStability call (the rest checks and the final verdict);
// - polish: the default solve (polish = true, and with it Newton's takeover at damping events:
//   a shorter run than the plain one where Newton ends it), its set-up, estimates, assessments,
//   the time of its stiffness matrices and its whole wall time; medians of repeats made one
//   after the other, after those of the plain solve;
// - the rest: the steps themselves, the final residual and energies.
//
//   kd_profile SPEC      (benchmarks/spec.hpp; the default settings but max_time, no stops)
//
// Prints one JSON object: the solve's status, steps, residual and final q, and per repeat its
// wall time, set-up, estimates and assessments (s), and a bare step's time (s); with polish 1
// the default solve, polish = true (its times and parts, Newton iterations, residual, final q).
//

#include "bare-step.hpp"
#include "spec.hpp"

#include <algorithm>
#include <chrono>
#include <iostream>
#include <stdexcept>
#include <utility>

namespace
{
  typedef std::chrono::steady_clock Clock;

  /// Time spent in the wrapped calls of one solve.
  struct Profile
  {
    bool active = false;
    int depth = 0; // nesting of wrapped calls: only the outermost counts
    Clock::time_point start;
    double setup = -1.; // s from the solve's start to the end of the first estimate
    int estimates = 0, assessments = 0, stiffness = 0;
    double estimate_seconds = 0., assess_seconds = 0., stiffness_seconds = 0.;
  } profile;

  /// Times the outermost wrapped call and files it.
  class Timed
  {
  public:
    explicit Timed(int kind)
    : kind_(kind)
    , outer_(profile.active && profile.depth == 0)
    , start_(Clock::now())
    {
      ++profile.depth;
    }
    ~Timed()
    {
      --profile.depth;
      if (!outer_)
        return;
      const Clock::time_point end = Clock::now();
      const double s = std::chrono::duration<double>(end - start_).count();
      if (kind_ == 0 && profile.setup < 0.)
        profile.setup = std::chrono::duration<double>(end - profile.start).count();
      else if (kind_ == 0)
      {
        ++profile.estimates;
        profile.estimate_seconds += s;
      }
      else if (kind_ == 1)
      {
        ++profile.assessments;
        profile.assess_seconds += s;
      }
      else
      {
        ++profile.stiffness;
        profile.stiffness_seconds += s;
      }
    }

  private:
    int kind_;
    bool outer_;
    Clock::time_point start_;
  };

  typedef pinocchio::Model Model;
  typedef pinocchio::Data Data;
  typedef Eigen::VectorXd Vec;
  typedef Eigen::MatrixXd Mat;
  using pinsettle::ForceModel;
  using pinsettle::JointStops;
  using pinsettle::LoopConstraints;
  using pinsettle::StabilityReport;
  using pinsettle::TimeScale;
} // namespace

// The wrappers (mangled names of the functions in pinsettle's library; see CMakeLists.txt).
extern "C"
{
  TimeScale
  __real__ZN9pinsettle16computeTimeScaleERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelEbPKNSA_IdLin1ELin1ELi0ELin1ELin1EEE(
    const Model &, Data &, const Vec &, const ForceModel *, bool, const Mat *);
  TimeScale
  __wrap__ZN9pinsettle16computeTimeScaleERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelEbPKNSA_IdLin1ELin1ELi0ELin1ELin1EEE(
    const Model & model,
    Data & data,
    const Vec & q,
    const ForceModel * forces,
    bool scale,
    const Mat * stiffness)
  {
    Timed timed(0);
    return __real__ZN9pinsettle16computeTimeScaleERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelEbPKNSA_IdLin1ELin1ELi0ELin1ELin1EEE(
      model, data, q, forces, scale, stiffness);
  }

  StabilityReport
  __real__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model &, Data &, const Vec &, const ForceModel *);
  StabilityReport
  __wrap__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model & model, Data & data, const Vec & q, const ForceModel * forces)
  {
    Timed timed(1);
    return __real__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
      model, data, q, forces);
  }

  StabilityReport
  __real__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKNS_10JointStopsERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model &, Data &, const JointStops &, const Vec &, const ForceModel *);
  StabilityReport
  __wrap__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKNS_10JointStopsERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model & model,
    Data & data,
    const JointStops & stops,
    const Vec & q,
    const ForceModel * forces)
  {
    Timed timed(1);
    return __real__ZN9pinsettle15assessStabilityERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKNS_10JointStopsERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
      model, data, stops, q, forces);
  }

  Mat __real__ZN9pinsettle22computeStiffnessMatrixERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model &, Data &, const Vec &, const ForceModel *);
  Mat __wrap__ZN9pinsettle22computeStiffnessMatrixERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
    const Model & model, Data & data, const Vec & q, const ForceModel * forces)
  {
    Timed timed(2);
    return __real__ZN9pinsettle22computeStiffnessMatrixERKN9pinocchio8ModelTplIdLi0ENS0_25JointCollectionDefaultTplEEERNS0_7DataTplIdLi0ES2_EERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEEPKNS_10ForceModelE(
      model, data, q, forces);
  }
}

namespace
{
  struct Solve
  {
    pinsettle::Result result;
    Profile profile;
  };

  Solve profiledSolve(
    const Model & model, const Vec & q0, const ForceModel * forces, bool polish, double max_time)
  {
    pinsettle::Settings settings; // the defaults, within the spec's wall-clock budget
    settings.polish = polish;
    settings.max_time = max_time;
    pinsettle::Solver solver(model);
    profile = Profile();
    profile.active = true;
    profile.start = Clock::now();
    Solve out;
    out.result = solver.solve(q0, settings, forces);
    profile.active = false;
    // Every solve makes a first step estimate. None seen means the library made its calls inside
    // one translation unit, where ld --wrap does not reach them: the parts would all be wrong.
    if (profile.setup < 0.)
      throw std::runtime_error(
        "no call of pinsettle::computeTimeScale reached this program's wrapper: the library "
        "calls it from inside stability.cpp's translation unit (CMakeLists.txt: stability.cpp "
        "must share its unity group with none of its callers)");
    out.profile = profile;
    return out;
  }

  // Fewest and most bare steps timed per repeat.
  constexpr long kMinBareSteps = 2000, kBareSteps = 20000;

  std::string list(const std::vector<double> & x)
  {
    return bench::jsonVector(x);
  }

  // Whether to make repeat r, `spent` seconds into the repeats: the first always.
  bool repeatAgain(const bench::Spec & spec, int r, double spent)
  {
    return r < spec.repeats && (r == 0 || spent < spec.repeat_budget);
  }

  // The plain solves (polish = false), per repeat: the wall time, its parts (s) and a bare
  // step's time (s); and the last solve.
  struct PlainSolves
  {
    std::vector<double> wall, setup, estimates, assess, bare;
    Solve last;
  };

  PlainSolves timePlainSolves(
    const Model & model, const bench::Spec & spec, const ForceModel * forces)
  {
    PlainSolves out;
    // With repeats, one solve first, untimed: the first in a process pays for cold caches and
    // first allocations, which a solve in a running program does not.
    if (spec.repeats > 1)
      profiledSolve(model, spec.q0, forces, false, spec.max_time);
    double spent = 0.;
    for (int r = 0; repeatAgain(spec, r, spent); ++r)
    {
      Solve plain = profiledSolve(model, spec.q0, forces, false, spec.max_time);
      out.wall.push_back(plain.result.info.wall_time);
      out.setup.push_back(plain.profile.setup);
      out.estimates.push_back(plain.profile.estimate_seconds);
      out.assess.push_back(plain.profile.assess_seconds);
      spent += plain.result.info.wall_time;
      // A bare step (aba + integrate) from the start, at a tenth of the solver's final step (a
      // fixed step that large may blow up; ABA costs the same whatever the step), timed over
      // the solve's steps, at least kMinBareSteps and at most kBareSteps.
      const long steps =
        std::clamp<long>(static_cast<long>(plain.result.info.steps), kMinBareSteps, kBareSteps);
      out.bare.push_back(
        bench::timeBareAbaStep(model, spec.q0, steps, 0.1 * plain.result.info.dt, "bare step"));
      out.last = std::move(plain);
    }
    return out;
  }

  // The default solves (polish = true), per repeat: the wall time and its parts (s); and the
  // last solve. None without spec.polish.
  struct PolishedSolves
  {
    std::vector<double> wall, setup, estimates, assess, stiffness;
    Solve last;
  };

  PolishedSolves timePolishedSolves(
    const Model & model, const bench::Spec & spec, const ForceModel * forces)
  {
    PolishedSolves out;
    if (!spec.polish)
      return out;
    // One after the other, as benchmarks/baselines.cpp repeats a baseline's run (a fresh solver
    // each, as it makes a fresh workspace): interleaved with the plain solves and the bare
    // steps, each would start from caches those left to it.
    if (spec.repeats > 1)
      profiledSolve(model, spec.q0, forces, true, spec.max_time);
    double spent = 0.;
    for (int r = 0; repeatAgain(spec, r, spent); ++r)
    {
      Solve polished = profiledSolve(model, spec.q0, forces, true, spec.max_time);
      out.wall.push_back(polished.result.info.wall_time);
      out.setup.push_back(polished.profile.setup);
      out.estimates.push_back(polished.profile.estimate_seconds);
      out.assess.push_back(polished.profile.assess_seconds);
      out.stiffness.push_back(polished.profile.stiffness_seconds);
      spent += polished.result.info.wall_time;
      out.last = std::move(polished);
    }
    return out;
  }

  void printPlain(const PlainSolves & plain)
  {
    const pinsettle::Result & r = plain.last.result;
    std::cout << "{\"status\": \"" << pinsettle::toString(r.status)
              << "\", \"steps\": " << r.info.steps << ", \"dt_estimates\": " << r.info.dt_estimates
              << ", \"residual\": " << bench::number(r.residual)
              << ", \"wall\": " << list(plain.wall) << ", \"setup\": " << list(plain.setup)
              << ", \"estimates\": " << list(plain.estimates)
              << ", \"estimate_count\": " << plain.last.profile.estimates
              << ", \"assessments\": " << list(plain.assess)
              << ", \"assessment_count\": " << plain.last.profile.assessments
              << ", \"bare_step\": " << list(plain.bare) << ", \"q\": " << bench::jsonVector(r.q);
  }

  void printPolished(const PolishedSolves & polish)
  {
    const Solve & polished = polish.last;
    std::cout << ", \"polish_wall\": " << list(polish.wall)
              << ", \"polish_setup\": " << list(polish.setup)
              << ", \"polish_estimates\": " << list(polish.estimates)
              << ", \"polish_assessments\": " << list(polish.assess)
              << ", \"polish_assessment_count\": " << polished.profile.assessments
              << ", \"polish_stiffness\": " << list(polish.stiffness)
              << ", \"polish_stiffness_count\": " << polished.profile.stiffness
              << ", \"polish_iterations\": " << polished.result.info.polish_iterations
              << ", \"polished\": " << (polished.result.info.polished ? "true" : "false")
              << ", \"polish_steps\": " << polished.result.info.steps
              << ", \"polish_residual\": " << bench::number(polished.result.residual)
              << ", \"polish_q\": " << bench::jsonVector(polished.result.q);
  }
} // namespace

int main(int argc, char ** argv)
{
  if (argc != 2)
  {
    std::cerr << "usage: " << argv[0] << " SPEC\n";
    return 2;
  }
  try
  {
    const bench::Spec spec = bench::readSpec(argv[1]);
    const Model model = bench::loadModel(spec);
    pinsettle::ForceElements elements(model);
    bench::addElements(elements, spec);
    const ForceModel * forces = elements.empty() ? nullptr : &elements;
    const PlainSolves plain = timePlainSolves(model, spec, forces);
    const PolishedSolves polished = timePolishedSolves(model, spec, forces);
    printPlain(plain);
    if (spec.polish)
      printPolished(polished);
    std::cout << "}\n";
  }
  catch (const std::exception & e)
  {
    std::cerr << argv[0] << ": " << e.what() << "\n";
    return 1;
  }
  return 0;
}
