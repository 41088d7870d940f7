//
// What baselines.cpp and kd_profile.cpp share: the scene spec benchmarks/report.py writes (the
// model saved by Python, the start, the force elements, the run's budget), a workspace sized
// once, the static force, forward dynamics and semi-implicit Euler on it, and JSON numbers.
//
// SPEC is a text file, one "key values..." per line:
//   model PATH           the (reduced) pinocchio::Model, saved by Python with saveToBinary
//   q0 nq x...           start configuration (at rest)
//   method NAME          baselines: viscous, mass_damping, adr, fire, fire2 or newton;
//                        kd_profile: kd
//   metric euclid|mass   FIRE's velocity mixing: Euclidean in joint coordinates, or in the
//                        mass-matrix metric (|v|_M, direction M^-1 F)
//   dt_safety X          viscous: the step as a fraction of the stability limit at the start
//   dt_max X             FIRE: dt_max as a multiple of the stability limit at the start
//                        (dt0 = dt_max / 10)
//   damping_factor X     viscous: c as a multiple of the rule's c (from the start)
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
//   polish 0|1           kd_profile: also time the solve with polish = true
//   newton 0|1           baselines: finish with the solver's Newton (takeover and polish)
//   radius X             newton: the trust region's first radius (rad or m)
//   joint_spring JOINT K REST D
//   point_spring FRAME_A AX AY AZ FRAME_B BX BY BZ K REST_LENGTH D
//   joint_load JOINT N E_1 .. E_N
//   point_load FRAME PX PY PZ FX FY FZ TX TY TZ
//

#ifndef __pinsettle_benchmarks_spec_hpp__
#define __pinsettle_benchmarks_spec_hpp__

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/serialization.hpp>

#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace bench
{
  struct Spec
  {
    std::string model_path, method, metric = "euclid", samples_path;
    Eigen::VectorXd q0;
    double dt_safety = 0.2, dt_max = 2., damping_factor = 1., target = 0., max_time = 60.,
           repeat_budget = 2., radius = 0.1;
    long check_every = 64, max_steps = 1000000, max_samples = 4000;
    int repeats = 1;
    bool polish = false, newton = false;
    std::vector<std::string> elements; // element lines, applied once the model is loaded
  };

  // A value of a spec line into its field of the spec.
  template<typename T, T Spec::* field>
  void readValue(std::istream & words, const std::string &, Spec & spec)
  {
    words >> spec.*field;
  }

  // q0 nq x...
  inline void readStart(std::istream & words, const std::string &, Spec & spec)
  {
    long n;
    words >> n;
    spec.q0.resize(n);
    for (long k = 0; k < n; ++k)
      words >> spec.q0[k];
  }

  // A force element's line, applied once the model is loaded (addElement).
  inline void keepElement(std::istream &, const std::string & line, Spec & spec)
  {
    spec.elements.push_back(line);
  }

  struct SpecKey
  {
    const char * key;
    void (*read)(std::istream & words, const std::string & line, Spec & spec);
  };

  // The keys of a spec file and how each line's values are read (see the top of the file).
  inline const SpecKey * findSpecKey(const std::string & key)
  {
    static const SpecKey keys[] = {
      {"model", readValue<std::string, &Spec::model_path>},
      {"method", readValue<std::string, &Spec::method>},
      {"metric", readValue<std::string, &Spec::metric>},
      {"samples", readValue<std::string, &Spec::samples_path>},
      {"q0", readStart},
      {"dt_safety", readValue<double, &Spec::dt_safety>},
      {"dt_max", readValue<double, &Spec::dt_max>},
      {"damping_factor", readValue<double, &Spec::damping_factor>},
      {"target", readValue<double, &Spec::target>},
      {"max_time", readValue<double, &Spec::max_time>},
      {"repeat_budget", readValue<double, &Spec::repeat_budget>},
      {"check_every", readValue<long, &Spec::check_every>},
      {"max_steps", readValue<long, &Spec::max_steps>},
      {"max_samples", readValue<long, &Spec::max_samples>},
      {"repeats", readValue<int, &Spec::repeats>},
      {"polish", readValue<bool, &Spec::polish>},
      {"newton", readValue<bool, &Spec::newton>},
      {"radius", readValue<double, &Spec::radius>},
      {"joint_spring", keepElement},
      {"point_spring", keepElement},
      {"joint_load", keepElement},
      {"point_load", keepElement},
    };
    for (const SpecKey & entry : keys)
      if (key == entry.key)
        return &entry;
    return nullptr;
  }

  // One line of the spec file at path (blank lines are skipped).
  inline void readSpecLine(const std::string & line, const std::string & path, Spec & spec)
  {
    std::istringstream words(line);
    std::string key;
    if (!(words >> key))
      return;
    const SpecKey * entry = findSpecKey(key);
    if (entry == nullptr)
      throw std::runtime_error("unknown key '" + key + "' in " + path);
    entry->read(words, line, spec);
    if (words.fail())
      throw std::runtime_error("bad line in " + path + ": " + line);
  }

  inline Spec readSpec(const std::string & path)
  {
    std::ifstream in(path);
    if (!in)
      throw std::runtime_error("cannot read " + path);
    Spec spec;
    std::string line;
    while (std::getline(in, line))
      readSpecLine(line, path, spec);
    if (spec.metric != "euclid" && spec.metric != "mass")
      throw std::runtime_error("metric must be euclid or mass, got '" + spec.metric + "'");
    return spec;
  }

  inline void addElement(pinsettle::ForceElements & elements, const std::string & line)
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

  // The spec's model, checked against its start.
  inline pinocchio::Model loadModel(const Spec & spec)
  {
    pinocchio::Model model;
    model.loadFromBinary(spec.model_path);
    if (spec.q0.size() != model.nq)
      throw std::runtime_error("q0 does not match the model's nq");
    return model;
  }

  inline void addElements(pinsettle::ForceElements & elements, const Spec & spec)
  {
    for (const std::string & line : spec.elements)
      addElement(elements, line);
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
  inline void appliedForces(
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
  inline void staticForce(
    const pinocchio::Model & model, const pinsettle::ForceElements * elements, Workspace & w)
  {
    appliedForces(model, elements, w.q, w.zero, w);
    if (elements != nullptr && elements->hasExternalForces())
      w.force = pinocchio::rnea(model, w.data, w.q, w.zero, w.zero, w.fext);
    else
      w.force = pinocchio::computeGeneralizedGravity(model, w.data, w.q);
    w.force -= w.tau;
  }

  // max |tau_static(q)| at w.q (N m or N), leaving tau_static in w.force.
  inline double staticResidual(
    const pinocchio::Model & model, const pinsettle::ForceElements * elements, Workspace & w)
  {
    staticForce(model, elements, w);
    return w.force.lpNorm<Eigen::Infinity>();
  }

  // Forward dynamics at (q, v) with the applied efforts in w.tau (and w.fext): w.data.ddq. In
  // the world convention, as the solver's step: the faster one, for every method alike.
  inline void forwardDynamics(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v,
    Workspace & w)
  {
    const pinocchio::Convention world = pinocchio::Convention::WORLD;
    if (elements != nullptr && elements->hasExternalForces())
      pinsettle::prebuilt::aba(model, w.data, q, v, w.tau, w.fext, world);
    else
      pinsettle::prebuilt::aba(model, w.data, q, v, w.tau, world);
  }

  // q moved by h v on the configuration manifold; false when a value turned non-finite.
  inline bool moveBy(const pinocchio::Model & model, double h, Workspace & w)
  {
    w.dq.noalias() = h * w.v;
    pinocchio::integrate(model, w.q, w.dq, w.q_next);
    w.q.swap(w.q_next);
    return w.q.allFinite() && w.v.allFinite();
  }

  // A number as JSON (as Python's json module reads it: NaN and Infinity spelled out).
  inline std::string number(double x)
  {
    if (std::isnan(x))
      return "NaN";
    if (std::isinf(x))
      return x > 0 ? "Infinity" : "-Infinity";
    std::ostringstream os;
    os << std::setprecision(17) << x;
    return os.str();
  }

  template<typename Vector>
  std::string jsonVector(const Vector & x)
  {
    std::string out = "[";
    for (Eigen::Index k = 0; k < static_cast<Eigen::Index>(x.size()); ++k)
      out += (k ? ", " : "") + number(x[k]);
    return out + "]";
  }
} // namespace bench

#endif // ifndef __pinsettle_benchmarks_spec_hpp__
