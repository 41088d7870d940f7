//
// The baselines of the benchmark report (benchmarks/report.py), on the same Pinocchio dynamics
// as pinsettle's solver and timed the same way (std::chrono::steady_clock around the loop):
//
//   viscous  plain viscous damping, what users of physics simulators do to let a robot settle:
//            a = ABA(q, v, tau_elements(q, v) - c v), the same damper c on every joint,
//            semi-implicit Euler with a fixed step.
//   mass_damping  viscous damping proportional to the mass matrix (dynamic relaxation's
//            classic form): a = ABA(q, v, tau_elements(q, v)) - c v, which damps every mode at the
//            same rate c / 2 (where the joint dampers damp light links far faster than heavy ones).
//   fire     FIRE (Bitzek et al., 2006) with its classic parameters: the power P = F . v of the
//            static force F = -tau_static(q) is watched; P <= 0 zeroes the velocity, halves the
//            step and resets the mixing; P > 0 mixes the velocity toward F,
//            v <- (1 - alpha) v + alpha |v| F / |F|, and after N_min such steps grows the step
//            (x f_inc, at most dt_max = 10 dt0) and shrinks alpha (x f_alpha). The motion is the
//            same semi-implicit Euler on ABA; every step also evaluates F (one RNEA).
//
//   baselines SPEC
//
// SPEC is a text file written by report.py, one "key values..." per line:
//   model PATH           the (reduced) pinocchio::Model, saved by Python with saveToBinary
//   q0 nq x...           start configuration (at rest)
//   method viscous|mass_damping|fire
//   dt X                 (initial) time step, s
//   damping C            viscous coefficient c (N m s/rad or N s/m on every joint; 1/s for
//                        mass_damping)
//   target R             stop once max |tau_static(q)| <= R (N m or N)
//   check_every N        steps between residual checks (viscous; FIRE has F every step)
//   max_steps N
//   max_time S           wall-clock budget per run, s
//   repeats N            timed runs (identical trajectories); no more once they took
//                        repeat_budget seconds in all
//   repeat_budget S
//   samples PATH         where the recorded run writes its samples: float64 rows
//                        [step, q_0 .. q_nq-1], at most max_samples rows plus the final state
//   max_samples N
//   joint_spring JOINT K REST D
//   point_spring FRAME_A AX AY AZ FRAME_B BX BY BZ K REST_LENGTH D
//   joint_load JOINT N E_1 .. E_N
//   point_load FRAME PX PY PZ FX FY FZ TX TY TZ
//
// A run that blows up (non-finite values, or a residual 1e6 times the start's) is tried again
// with half the step, up to 6 times. Prints one JSON object: status (converged, max_steps,
// time_limit or diverged), steps, the wall time of each timed run, the final residual, q, the
// step used and the halvings, and for FIRE the step at the end and the velocity resets.
//

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/serialization.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace
{
  typedef std::chrono::steady_clock Clock;

  struct Spec
  {
    std::string model_path, method, samples_path;
    Eigen::VectorXd q0;
    double dt = 0., damping = 0., target = 0., max_time = 60., repeat_budget = 2.;
    long check_every = 64, max_steps = 1000000, max_samples = 4000;
    int repeats = 1;
    std::vector<std::string> elements; // element lines, applied once the model is loaded
  };

  Spec readSpec(const std::string & path)
  {
    std::ifstream in(path);
    if (!in)
      throw std::runtime_error("cannot read " + path);
    Spec spec;
    std::string line;
    while (std::getline(in, line))
    {
      std::istringstream words(line);
      std::string key;
      if (!(words >> key))
        continue;
      if (key == "model")
        words >> spec.model_path;
      else if (key == "method")
        words >> spec.method;
      else if (key == "samples")
        words >> spec.samples_path;
      else if (key == "q0")
      {
        long n;
        words >> n;
        spec.q0.resize(n);
        for (long k = 0; k < n; ++k)
          words >> spec.q0[k];
      }
      else if (key == "dt")
        words >> spec.dt;
      else if (key == "damping")
        words >> spec.damping;
      else if (key == "target")
        words >> spec.target;
      else if (key == "max_time")
        words >> spec.max_time;
      else if (key == "repeat_budget")
        words >> spec.repeat_budget;
      else if (key == "check_every")
        words >> spec.check_every;
      else if (key == "max_steps")
        words >> spec.max_steps;
      else if (key == "max_samples")
        words >> spec.max_samples;
      else if (key == "repeats")
        words >> spec.repeats;
      else if (
        key == "joint_spring" || key == "point_spring" || key == "joint_load"
        || key == "point_load")
        spec.elements.push_back(line);
      else
        throw std::runtime_error("unknown key '" + key + "' in " + path);
      if (words.fail())
        throw std::runtime_error("bad line in " + path + ": " + line);
    }
    return spec;
  }

  void addElement(pinsettle::ForceElements & elements, const std::string & line)
  {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "joint_spring")
    {
      long joint;
      double k, rest, d;
      words >> joint >> k >> rest >> d;
      elements.addJointSpring(static_cast<pinocchio::JointIndex>(joint), k, rest, d);
    }
    else if (key == "point_spring")
    {
      long fa, fb;
      Eigen::Vector3d a, b;
      double k, rest, d;
      words >> fa >> a[0] >> a[1] >> a[2] >> fb >> b[0] >> b[1] >> b[2] >> k >> rest >> d;
      elements.addPointSpring(
        static_cast<pinocchio::FrameIndex>(fa), a, static_cast<pinocchio::FrameIndex>(fb), b, k,
        rest, d);
    }
    else if (key == "joint_load")
    {
      long joint, n;
      words >> joint >> n;
      Eigen::VectorXd effort(n);
      for (long k = 0; k < n; ++k)
        words >> effort[k];
      elements.addJointLoad(static_cast<pinocchio::JointIndex>(joint), effort);
    }
    else // point_load
    {
      long frame;
      Eigen::Vector3d p, f, t;
      words >> frame >> p[0] >> p[1] >> p[2] >> f[0] >> f[1] >> f[2] >> t[0] >> t[1] >> t[2];
      elements.addPointLoad(static_cast<pinocchio::FrameIndex>(frame), p, f, t);
    }
    if (words.fail())
      throw std::runtime_error("bad element line: " + line);
  }

  // The loops' state and workspace, sized once: nothing is allocated per step.
  struct Workspace
  {
    explicit Workspace(const pinocchio::Model & model)
    : data(model)
    , q(model.nq)
    , q_next(model.nq)
    , v(model.nv)
    , dq(model.nv)
    , tau(model.nv)
    , force(model.nv)
    , zero(Eigen::VectorXd::Zero(model.nv))
    , fext(model.joints.size(), pinocchio::Force::Zero())
    {
    }
    pinocchio::Data data;
    Eigen::VectorXd q, q_next, v, dq, tau, force, zero;
    pinsettle::ForceVector fext;
  };

  // The applied efforts at (q, v) into w.tau (and w.fext when the elements have point forces).
  void appliedForces(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    Workspace & w)
  {
    w.tau.setZero();
    if (elements == nullptr)
      return;
    if (elements->hasExternalForces())
      for (pinocchio::Force & f : w.fext)
        f.setZero();
    elements->computeForces(model, w.data, q, v, w.tau, w.fext);
  }

  // The net static generalized force tau_static(q) (gravity minus springs and loads, as
  // pinsettle::computeStaticForce) into w.force, without allocating.
  void staticForce(
    const pinocchio::Model & model, const pinsettle::ForceElements * elements, Workspace & w)
  {
    appliedForces(model, elements, w.q, w.zero, w);
    if (elements != nullptr && elements->hasExternalForces())
      w.force = pinocchio::rnea(model, w.data, w.q, w.zero, w.zero, w.fext);
    else
      w.force = pinocchio::computeGeneralizedGravity(model, w.data, w.q);
    w.force -= w.tau;
  }

  // Forward dynamics at (w.q, w.v) with the applied efforts in w.tau (and w.fext).
  void forwardDynamics(
    const pinocchio::Model & model, const pinsettle::ForceElements * elements, Workspace & w)
  {
    if (elements != nullptr && elements->hasExternalForces())
      pinocchio::aba(model, w.data, w.q, w.v, w.tau, w.fext);
    else
      pinocchio::aba(model, w.data, w.q, w.v, w.tau);
  }

  // Semi-implicit Euler on the configuration manifold; false when a value turned non-finite.
  bool integrate(const pinocchio::Model & model, double h, Workspace & w)
  {
    w.v.noalias() += h * w.data.ddq;
    w.dq.noalias() = h * w.v;
    pinocchio::integrate(model, w.q, w.dq, w.q_next);
    w.q.swap(w.q_next);
    return w.q.allFinite() && w.v.allFinite();
  }

  struct Outcome
  {
    std::string status = "max_steps";
    long steps = 0;
    double residual = 0., dt = 0., seconds = 0.;
    long resets = 0;
    Eigen::VectorXd q;
  };

  // Records [step, q] every `every` steps (every = 0: nothing).
  struct Recorder
  {
    long every = 0;
    std::vector<double> rows;
    void record(long step, const Eigen::VectorXd & q)
    {
      if (every == 0 || step % every != 0)
        return;
      rows.push_back(static_cast<double>(step));
      rows.insert(rows.end(), q.data(), q.data() + q.size());
    }
  };

  // FIRE's classic parameters (Bitzek et al., 2006).
  constexpr int kFireNMin = 5;
  constexpr double kFireFInc = 1.1, kFireFDec = 0.5, kFireAlphaStart = 0.1, kFireFAlpha = 0.99,
                   kFireDtMax = 10.;
  // A residual this many times the start's, or a non-finite value, is a divergence.
  constexpr double kBlowUp = 1e6;
  // Step halvings tried on a divergence.
  constexpr int kMaxHalvings = 6;

  Outcome run(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    const Spec & spec,
    Recorder & recorder)
  {
    Workspace w(model);
    w.q = spec.q0;
    w.v.setZero();
    const bool fire = spec.method == "fire", viscous = spec.method == "viscous",
               mass_damping = spec.method == "mass_damping";
    double dt = spec.dt, alpha = kFireAlphaStart;
    const double dt_max = kFireDtMax * spec.dt;
    int positive = 0;
    Outcome out;
    staticForce(model, elements, w);
    const double start_residual = w.force.lpNorm<Eigen::Infinity>();
    const Clock::time_point start = Clock::now();
    long step = 0;
    for (; step < spec.max_steps; ++step)
    {
      recorder.record(step, w.q);
      if (fire || step % spec.check_every == 0)
      {
        staticForce(model, elements, w);
        const double residual = w.force.lpNorm<Eigen::Infinity>();
        if (!(residual <= kBlowUp * start_residual)) // also catches NaN
        {
          out.status = "diverged";
          break;
        }
        if (residual <= spec.target)
        {
          out.status = "converged";
          break;
        }
        if (
          step % 1024 == 0
          && std::chrono::duration<double>(Clock::now() - start).count() > spec.max_time)
        {
          out.status = "time_limit";
          break;
        }
      }
      if (fire)
      {
        // w.force is tau_static; the force driving the mechanism toward rest is its opposite.
        const double power = -w.force.dot(w.v);
        if (power > 0.)
        {
          const double force_norm = w.force.norm();
          if (force_norm > 0.)
            w.v = (1. - alpha) * w.v - (alpha * w.v.norm() / force_norm) * w.force;
          if (positive > kFireNMin)
          {
            dt = std::min(dt * kFireFInc, dt_max);
            alpha *= kFireFAlpha;
          }
          ++positive;
        }
        else
        {
          w.v.setZero();
          dt *= kFireFDec;
          alpha = kFireAlphaStart;
          positive = 0;
          ++out.resets;
        }
      }
      appliedForces(model, elements, w.q, w.v, w);
      if (viscous)
        w.tau.noalias() -= spec.damping * w.v;
      forwardDynamics(model, elements, w);
      if (mass_damping)
        w.data.ddq.noalias() -= spec.damping * w.v;
      if (!integrate(model, dt, w))
      {
        out.status = "diverged";
        ++step;
        break;
      }
    }
    out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    out.steps = step;
    out.dt = dt;
    out.q = w.q;
    staticForce(model, elements, w);
    out.residual = w.force.lpNorm<Eigen::Infinity>();
    return out;
  }

  // A number as JSON (as Python's json module reads it: NaN and Infinity spelled out).
  std::string number(double x)
  {
    if (std::isnan(x))
      return "NaN";
    if (std::isinf(x))
      return x > 0 ? "Infinity" : "-Infinity";
    std::ostringstream os;
    os << std::setprecision(17) << x;
    return os.str();
  }

  void printVector(std::ostream & os, const Eigen::VectorXd & x)
  {
    os << "[";
    for (Eigen::Index k = 0; k < x.size(); ++k)
      os << (k ? ", " : "") << number(x[k]);
    os << "]";
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
    const Spec spec = readSpec(argv[1]);
    pinocchio::Model model;
    model.loadFromBinary(spec.model_path);
    if (spec.q0.size() != model.nq)
      throw std::runtime_error("q0 does not match the model's nq");
    if (spec.method != "viscous" && spec.method != "mass_damping" && spec.method != "fire")
      throw std::runtime_error(
        "method must be viscous, mass_damping or fire, got '" + spec.method + "'");
    pinsettle::ForceElements elements(model);
    for (const std::string & line : spec.elements)
      addElement(elements, line);
    const pinsettle::ForceElements * forces = elements.empty() ? nullptr : &elements;

    // A run that blows up is tried again with half the step, up to kMaxHalvings times.
    Spec used = spec;
    Recorder none;
    Outcome out = run(model, forces, used, none);
    int halvings = 0;
    for (; out.status == "diverged" && halvings < kMaxHalvings; ++halvings)
    {
      used.dt *= 0.5;
      out = run(model, forces, used, none);
    }
    std::vector<double> seconds{out.seconds};
    double spent = out.seconds;
    for (int r = 1; r < spec.repeats && spent < spec.repeat_budget; ++r)
    {
      out = run(model, forces, used, none);
      seconds.push_back(out.seconds);
      spent += out.seconds;
    }
    if (!spec.samples_path.empty())
    {
      // The same run again, recording: its trajectory is the one timed above.
      Recorder recorder;
      recorder.every = std::max<long>(1, (out.steps + spec.max_samples - 1) / spec.max_samples);
      const Outcome recorded = run(model, forces, used, recorder);
      // The final state, unless it is the last sample already (a run that stops on the
      // residual check stops right after recording).
      const std::size_t row = static_cast<std::size_t>(model.nq) + 1;
      if (
        recorder.rows.size() < row
        || recorder.rows[recorder.rows.size() - row] != static_cast<double>(recorded.steps))
      {
        recorder.rows.push_back(static_cast<double>(recorded.steps));
        recorder.rows.insert(recorder.rows.end(), recorded.q.data(), recorded.q.data() + model.nq);
      }
      std::ofstream file(spec.samples_path, std::ios::binary);
      file.write(
        reinterpret_cast<const char *>(recorder.rows.data()),
        static_cast<std::streamsize>(recorder.rows.size() * sizeof(double)));
      if (recorded.steps != out.steps && out.status != "time_limit")
        throw std::runtime_error("the recorded run took another path than the timed runs");
    }

    std::cout << "{\"method\": \"" << spec.method << "\", \"status\": \"" << out.status
              << "\", \"steps\": " << out.steps << ", \"wall_times\": ";
    printVector(std::cout, Eigen::Map<const Eigen::VectorXd>(seconds.data(), seconds.size()));
    std::cout << ", \"residual\": " << number(out.residual) << ", \"dt\": " << number(used.dt)
              << ", \"dt_end\": " << number(out.dt) << ", \"halvings\": " << halvings
              << ", \"resets\": " << out.resets << ", \"q\": ";
    printVector(std::cout, out.q);
    std::cout << "}\n";
  }
  catch (const std::exception & e)
  {
    std::cerr << argv[0] << ": " << e.what() << "\n";
    return 1;
  }
  return 0;
}
