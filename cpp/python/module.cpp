//
// Copyright (c) 2026 pinsettle contributors
//
// The Python module pinsettle._core: the only translation unit that includes pybind11.
// Pinocchio's Python objects are Boost.Python objects; they are read here by reference through
// boost::python::extract, so a model is never copied.
//

#include <pinocchio/bindings/python/pybind11.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include "pinsettle/constraint-set.hpp"
#include "pinsettle/setting-fields.hpp"
#include "pinsettle/elements.hpp"
#include "pinsettle/energy.hpp"
#include "pinsettle/loops.hpp"
#include "pinsettle/model-checks.hpp"
#include "pinsettle/stops.hpp"
#include "pinsettle/solver.hpp"
#include "pinsettle/stability.hpp"

#include <cmath>
#include <memory>
#include <optional>
#include <sstream>
#include <unordered_map>

namespace py = pybind11;
namespace bp = boost::python;
using namespace pinsettle;

namespace
{
  // A setting that is 'auto' (stored as 0) or a number.
  py::object autoOrNumber(double value)
  {
    return value == 0. ? py::object(py::str("auto")) : py::object(py::float_(value));
  }

  // 'auto' as 0, or the number if it is one accepts takes; the error names the setting.
  double parseAutoOrNumber(
    const py::object & value,
    const std::string & name,
    const std::string & numbers,
    bool (*accepts)(double))
  {
    const std::string expected = name + " must be 'auto' or " + numbers + ", got ";
    if (py::isinstance<py::str>(value))
    {
      if (value.cast<std::string>() != "auto")
        throw std::invalid_argument(expected + "'" + value.cast<std::string>() + "'");
      return 0.;
    }
    const double x = value.cast<double>();
    if (!accepts(x))
      throw std::invalid_argument(expected + py::repr(value).cast<std::string>());
    return x;
  }

  // True, False or 'auto' as a Toggle; anything else is refused with a message naming the
  // setting (a bool is checked first: py::bool_ is no str, and 1 is no bool).
  Toggle parseToggle(const py::object & value, const std::string & name, const std::string & takes)
  {
    if (py::isinstance<py::bool_>(value))
      return value.cast<bool>() ? Toggle::On : Toggle::Off;
    if (py::isinstance<py::str>(value) && value.cast<std::string>() == "auto")
      return Toggle::Auto;
    throw std::invalid_argument(
      name + " must be " + takes + ", got " + py::repr(value).cast<std::string>());
  }

  // The pinocchio::Model a Python object holds, refused with a message (ValueError) where the
  // algorithms do not support it, so that it is never run.
  const pinocchio::Model & supportedModel(const py::handle & obj, const char * name = "model")
  {
    bp::extract<pinocchio::Model &> model(obj.ptr());
    if (!model.check())
    {
      std::ostringstream msg;
      msg << name << " must be a pinocchio.Model (import pinocchio first), got "
          << py::str(py::type::handle_of(obj).attr("__qualname__")).cast<std::string>();
      throw py::type_error(msg.str());
    }
    checkSupportedModel(model());
    return model();
  }

  // Every entry point reads its model here: supportedModel, and one whose pinocchio::Data
  // would not fit in the memory available is refused (MemoryError) before any Data of it is
  // made, by pinsettle or by the Python code around it.
  const pinocchio::Model & modelFrom(const py::handle & obj, const char * name = "model")
  {
    const pinocchio::Model & model = supportedModel(obj, name);
    checkDataMemory(model, 1, "pinsettle");
    return model;
  }

  // The force elements of a scene, already resolved to joint and frame indices by the Python
  // layer (pinsettle/_scene.py), which names them in its messages: a dict of lists of tuples.
  std::unique_ptr<ForceElements> elementsFrom(
    const pinocchio::Model & model, const py::object & spec)
  {
    if (spec.is_none())
      return nullptr;
    auto elements = std::make_unique<ForceElements>(model);
    const py::dict d = spec.cast<py::dict>();
    auto list = [&](const char * key) {
      return d.contains(key) ? d[key].cast<py::list>() : py::list();
    };
    for (const py::handle & e : list("joint_springs"))
    {
      const auto t = e.cast<std::tuple<std::size_t, double, double, double>>();
      elements->addJointSpring(std::get<0>(t), std::get<1>(t), std::get<2>(t), std::get<3>(t));
    }
    for (const py::handle & e : list("springs"))
    {
      const auto t = e.cast<std::tuple<
        std::size_t, Eigen::Vector3d, std::size_t, Eigen::Vector3d, double, double, double>>();
      elements->addPointSpring(
        std::get<0>(t), std::get<1>(t), std::get<2>(t), std::get<3>(t), std::get<4>(t),
        std::get<5>(t), std::get<6>(t));
    }
    for (const py::handle & e : list("joint_loads"))
    {
      const auto t = e.cast<std::tuple<std::size_t, Eigen::VectorXd>>();
      elements->addJointLoad(std::get<0>(t), std::get<1>(t));
    }
    for (const py::handle & e : list("point_loads"))
    {
      const auto t =
        e.cast<std::tuple<std::size_t, Eigen::Vector3d, Eigen::Vector3d, Eigen::Vector3d>>();
      elements->addPointLoad(std::get<0>(t), std::get<1>(t), std::get<2>(t), std::get<3>(t));
    }
    return elements;
  }

  // Loop closures resolved to frame indices by the Python layer: a list of tuples
  // (frame_a, point_a, frame_b, point_b, kind, name), and joint couplings (mimic joints)
  // ("coupling", follower, leader, multiplier, offset, name); None or empty for a tree.
  std::unique_ptr<LoopConstraints> loopsFrom(
    const pinocchio::Model & model, const py::object & spec)
  {
    if (spec.is_none() || py::len(spec) == 0)
      return nullptr;
    auto loops = std::make_unique<LoopConstraints>(model);
    for (const py::handle & e : spec.cast<py::list>())
    {
      if (py::isinstance<py::str>(e.cast<py::tuple>()[0]))
      {
        const auto c =
          e.cast<std::tuple<std::string, std::size_t, std::size_t, double, double, std::string>>();
        loops->addCoupling(
          std::get<1>(c), std::get<2>(c), std::get<3>(c), std::get<4>(c), std::get<5>(c));
        continue;
      }
      const auto t = e.cast<std::tuple<
        std::size_t, Eigen::Vector3d, std::size_t, Eigen::Vector3d, std::string, std::string>>();
      const std::string & kind = std::get<4>(t);
      if (kind != "point" && kind != "frame")
        throw std::invalid_argument(
          std::get<5>(t) + ": kind must be 'point' or 'frame', got '" + kind + "'");
      loops->addLoop(
        std::get<0>(t), std::get<1>(t), std::get<2>(t), std::get<3>(t),
        kind == "point" ? LoopKind::Point : LoopKind::Frame, std::get<5>(t));
    }
    return loops;
  }

  // Joint stops: None for none, else (from_model, [(joint index, lower, upper), ...]) with the
  // model's position limits taken when from_model, then each entry adding or overriding a
  // joint's stops (an infinite bound: none on that side).
  std::unique_ptr<JointStops> stopsFrom(const pinocchio::Model & model, const py::object & spec)
  {
    if (spec.is_none())
      return nullptr;
    const auto t = spec.cast<std::tuple<bool, py::list>>();
    auto stops = std::make_unique<JointStops>(model, std::get<0>(t));
    for (const py::handle & e : std::get<1>(t))
    {
      const auto limit = e.cast<std::tuple<std::size_t, double, double>>();
      stops->setLimit(std::get<0>(limit), std::get<1>(limit), std::get<2>(limit));
    }
    return stops;
  }

  // Ground contacts: None for none, else ([(name, point, normal, friction)], [(name, centre,
  // axes (3 x 3), half sizes, friction)], [(name, joint index, position in the joint's frame,
  // radius)]).
  std::unique_ptr<GroundContacts> contactsFrom(
    const pinocchio::Model & model, const py::object & spec)
  {
    if (spec.is_none())
      return nullptr;
    const auto t = spec.cast<std::tuple<py::list, py::list, py::list>>();
    auto contacts = std::make_unique<GroundContacts>(model);
    for (const py::handle & e : std::get<0>(t))
    {
      const auto g = e.cast<std::tuple<std::string, Eigen::Vector3d, Eigen::Vector3d, double>>();
      contacts->addPlane(std::get<0>(g), std::get<1>(g), std::get<2>(g), std::get<3>(g));
    }
    for (const py::handle & e : std::get<1>(t))
    {
      const auto g = e.cast<
        std::tuple<std::string, Eigen::Vector3d, Eigen::Matrix3d, Eigen::Vector3d, double>>();
      contacts->addBox(
        std::get<0>(g), std::get<1>(g), std::get<2>(g), std::get<3>(g), std::get<4>(g));
    }
    for (const py::handle & e : std::get<2>(t))
    {
      const auto c = e.cast<std::tuple<std::string, std::size_t, Eigen::Vector3d, double>>();
      contacts->addPoint(std::get<0>(c), std::get<1>(c), std::get<2>(c), std::get<3>(c));
    }
    return contacts;
  }

  // The ground contacts of a rest: (name, ground, point, normal, normal force, tangential
  // force, gap, sticking, marginal) each.
  py::list groundContactsToList(const std::vector<GroundContact> & contacts)
  {
    py::list out;
    for (const GroundContact & c : contacts)
      out.append(
        py::make_tuple(
          c.name, c.ground, c.point, c.normal, c.normal_force, c.tangential_force, c.gap,
          c.sticking, c.marginal));
    return out;
  }

  py::list stopContactsToList(const pinocchio::Model & model, const std::vector<StopContact> & c)
  {
    py::list out;
    for (const StopContact & contact : c)
      out.append(
        py::make_tuple(model.names[contact.joint], toString(contact.side), contact.reaction));
    return out;
  }

  // A model read from Python, its force elements, loops and scratch data, for one evaluation
  // at q.
  struct Evaluation
  {
    const pinocchio::Model & model;
    std::unique_ptr<ForceElements> elements;
    std::unique_ptr<LoopConstraints> loops;
    pinocchio::Data data;
    std::unique_ptr<JointStops> stops;
  };

  Evaluation evaluationAt(
    const py::object & model_obj,
    const Eigen::VectorXd & q,
    const py::object & spec,
    const py::object & loops = py::none(),
    const py::object & stops = py::none())
  {
    const pinocchio::Model & model = modelFrom(model_obj);
    checkConfiguration(model, q, "q");
    return Evaluation{
      model, elementsFrom(model, spec), loopsFrom(model, loops), makeData(model, "the evaluation"),
      stopsFrom(model, stops)};
  }

  // The trace as arrays: samples (step, time, energies, optionally q) and events.
  py::dict traceToDict(const Result & r)
  {
    const Eigen::Index n = static_cast<Eigen::Index>(r.trace.samples.size());
    Eigen::Matrix<std::int64_t, Eigen::Dynamic, 1> step(n);
    Eigen::VectorXd time(n), energy(n), simplified(n);
    const bool with_q = r.trace.samples.front().q.size() > 0;
    Eigen::MatrixXd q(with_q ? n : 0, with_q ? r.q.size() : 0);
    for (Eigen::Index k = 0; k < n; ++k)
    {
      const TraceSample & s = r.trace.samples[static_cast<std::size_t>(k)];
      step[k] = s.step;
      time[k] = s.time;
      energy[k] = s.energy;
      simplified[k] = s.simplified_energy;
      if (with_q)
        q.row(k) = s.q.transpose();
    }
    const Eigen::Index m = static_cast<Eigen::Index>(r.trace.events.size());
    Eigen::Matrix<std::int64_t, Eigen::Dynamic, 1> event_step(m);
    Eigen::VectorXd event_time(m);
    Eigen::Matrix<std::int64_t, Eigen::Dynamic, 1> event_joint(m);
    py::list event_kind;
    for (Eigen::Index k = 0; k < m; ++k)
    {
      const TraceEvent & e = r.trace.events[static_cast<std::size_t>(k)];
      event_step[k] = e.step;
      event_time[k] = e.time;
      event_kind.append(toString(e.kind));
      event_joint[k] = e.kind == EventKind::Impact ? static_cast<std::int64_t>(e.joint) : -1;
    }
    py::dict trace;
    trace["step"] = step;
    trace["time"] = time;
    trace["kinetic_energy"] = energy;
    trace["simplified_kinetic_energy"] = simplified;
    trace["stride"] = r.trace.stride;
    trace["q"] = with_q ? py::object(py::cast(q)) : py::object(py::none());
    trace["event_step"] = event_step;
    trace["event_time"] = event_time;
    trace["event_kind"] = event_kind;
    trace["event_joint"] = event_joint;
    return trace;
  }

  // A key of the result's dict, made once and kept (interned): toDict runs after every solve,
  // where a key made from its C string each time is a measurable part of a short solve.
  py::handle internedKey(const char * name)
  {
    // Made once and never destroyed, as the interpreter keeps the strings to its end: a map
    // destroyed at exit would drop its references without releasing them (LeakSanitizer finds
    // them). Used with the GIL held.
    static auto & keys = *new std::unordered_map<const char *, PyObject *>();
    const auto found = keys.try_emplace(name, nullptr);
    if (found.second)
      found.first->second = PyUnicode_InternFromString(name);
    return found.first->second;
  }

  // A vector as a new numpy array (a copy: the result it comes from is gone after the call).
  py::array_t<double> toArray(const Eigen::VectorXd & x)
  {
    return py::array_t<double>(x.size(), x.data());
  }

  // 'm' for a prismatic joint, 'rad' for a revolute or helical one (a joint with a stop).
  const char * unitOf(const pinocchio::Model & model, pinocchio::JointIndex joint)
  {
    const std::string kind = model.joints[joint].shortname();
    const bool prismatic = kind == "JointModelPX" || kind == "JointModelPY"
                           || kind == "JointModelPZ" || kind.find("Prismatic") != std::string::npos;
    return prismatic ? "m" : "rad";
  }

  // The stops' fields of a result by joint name: at_limit (side), limit_reactions (>= 0),
  // start_clamped (how far the start was moved) and the unit of each joint named there.
  void nameStops(const pinocchio::Model & model, const Result & r, py::dict & out)
  {
    py::dict at_limit, reactions, clamped, units;
    for (const StopContact & contact : r.stop_contacts)
    {
      const py::str name(model.names[contact.joint]);
      at_limit[name] = internedKey(toString(contact.side));
      reactions[name] = contact.reaction;
      units[name] = internedKey(unitOf(model, contact.joint));
    }
    for (const std::pair<pinocchio::JointIndex, double> & c : r.info.start_clamped)
    {
      const py::str name(model.names[c.first]);
      clamped[name] = c.second;
      units[name] = internedKey(unitOf(model, c.first));
    }
    out[internedKey("at_limit")] = at_limit;
    out[internedKey("limit_reactions")] = reactions;
    out[internedKey("start_clamped")] = clamped;
    out[internedKey("units")] = units;
  }

  py::dict toDict(const pinocchio::Model & model, const Result & r)
  {
    py::dict out;
    const auto field = [&out](const char * name) { return out[internedKey(name)]; };
    nameStops(model, r, out);
    field("q") = toArray(r.q);
    field("v") = toArray(r.v);
    field("status") = internedKey(toString(r.status));
    field("steps") = r.info.steps;
    field("peaks") = r.info.peaks;
    field("pushes") = r.info.pushes;
    field("stability") = internedKey(toString(r.stability));
    field("min_stiffness_eigenvalue") = r.info.min_stiffness_eigenvalue;
    field("neutral_directions") = r.info.neutral_directions;
    field("sim_time") = r.info.sim_time;
    field("wall_time") = r.info.wall_time;
    field("kinetic_energy") = r.info.kinetic_energy;
    field("simplified_kinetic_energy") = r.info.simplified_kinetic_energy;
    field("residual") = r.residual;
    field("contacts") = groundContactsToList(r.ground_contacts);
    field("residual_before_polish") = r.info.residual_before_polish;
    field("polish_iterations") = r.info.polish_iterations;
    field("polished") = r.info.polished;
    field("dt") = r.info.dt;
    field("dt_estimates") = r.info.dt_estimates;
    field("dt_reductions") = r.info.dt_reductions;
    field("scaled_modes") = r.info.scaled_modes;
    field("scaled_joints") = r.info.scaled_joints;
    field("mobility") = r.info.mobility;
    field("assembly_distance") = r.info.assembly_distance;
    field("constraint_error") = r.constraint_error;
    field("reason") = r.reason;
    field("trace") = r.trace.samples.empty() ? py::object(py::none()) : py::object(traceToDict(r));
    return out;
  }

  py::dict progressDict(const RunProgress & p)
  {
    py::dict out;
    out["steps"] = p.steps;
    out["sim_time"] = p.sim_time;
    out["kinetic_energy"] = p.kinetic_energy;
    out["peaks"] = p.peaks;
    out["residual"] = p.residual();
    out["wall_time"] = p.wall_time;
    return out;
  }

  // The user's callback and Ctrl-C, polled by the loop with the GIL released in between:
  // Ctrl-C (SIGINT) ends the run as "aborted" and keeps the state; an exception from the
  // user's callback or progress ends it and is kept in error, to be re-raised.
  AbortCallback pollHook(
    const py::object & callback,
    const py::object & progress,
    std::optional<py::error_already_set> & error)
  {
    return [&error, callback, progress](const RunProgress & p) -> bool {
      py::gil_scoped_acquire gil;
      if (PyErr_CheckSignals() != 0)
      {
        if (PyErr_ExceptionMatches(PyExc_KeyboardInterrupt))
        {
          PyErr_Clear();
          return true;
        }
        error.emplace();
        return true;
      }
      try
      {
        // progress(dict) is told where the run stands at each poll; its value is ignored.
        if (!progress.is_none())
          progress(progressDict(p));
        if (callback.is_none())
          return false;
        return py::bool_(callback());
      }
      catch (py::error_already_set & e)
      {
        error.emplace(std::move(e));
        return true;
      }
    };
  }

  ///
  /// \brief The solver as Python holds it: built once from a model and what the scene adds to
  /// it (force elements, loop closures, joint stops), then solved from as many starts as
  /// wanted. It owns what it was given and keeps the Python model alive; its pinocchio::Data
  /// and workspace are allocated once, on construction.
  ///
  class BoundSolver
  {
  public:
    BoundSolver(
      const py::object & model_obj,
      const py::object & elements,
      const py::object & loops,
      const py::object & stops,
      const py::object & joints,
      const py::object & contacts)
    : model_obj_(model_obj)
    , model_(modelFrom(model_obj))
    , elements_(elementsFrom(model_, elements))
    , loops_(loopsFrom(model_, loops))
    , stops_(stopsFrom(model_, stops))
    , contacts_(contactsFrom(model_, contacts))
    , solver_(model_, loops_.get(), stops_.get(), contacts_.get())
    , equal_limits_(
        py::tuple(
          jointNames(stops_ ? stops_->equalLimitJoints() : std::vector<pinocchio::JointIndex>())))
    , unapplied_limits_(
        py::tuple(jointNames(
          stops_ ? stops_->unappliedLimitJoints() : std::vector<pinocchio::JointIndex>())))
    {
      if (!joints.is_none())
        for (const py::handle & j : joints)
          joints_.push_back(j.cast<JointField>());
    }

    /// The run from (q0, v0) (dim nq, nv) as a dict of the Result's fields (names of joints,
    /// the trace's samples as arrays).
    py::dict solve(
      const Eigen::VectorXd & q0,
      const Eigen::VectorXd & v0,
      const py::object & settings_obj,
      const py::object & callback,
      const py::object & progress)
    {
      const Settings & settings = settings_obj.cast<const Settings &>();
      std::optional<py::error_already_set> error;
      const AbortCallback hook = pollHook(callback, progress, error);
      Result result;
      {
        py::gil_scoped_release release;
        result = solver_.solve(q0, v0, settings, elements_.get(), hook);
      }
      if (error)
        throw std::move(*error);
      py::dict out = toDict(model_, result);
      out[internedKey("settings")] = settings_obj;
      out[internedKey("limits")] = py::bool_(stops_ != nullptr);
      out[internedKey("loops")] = loops_ ? loops_->loops().size() : std::size_t(0);
      out[internedKey("equal_limits")] = equal_limits_;
      out[internedKey("unapplied_limits")] = unapplied_limits_;
      if (!joints_.empty())
        out[internedKey("joints")] = jointValues(result.q);
      return out;
    }

    const py::object & model() const
    {
      return model_obj_;
    }

    /// Joints whose model limits were not applied as stops, by name: equal lower and upper
    /// limits (taken as no stop), or of several configuration entries (none applies).
    const py::tuple & equalLimits() const
    {
      return equal_limits_;
    }
    const py::tuple & unappliedLimits() const
    {
      return unapplied_limits_;
    }

  private:
    /// How a joint's value is read from q by name (given by the Python layer, which decides
    /// the layout): kind 0 a number q[iq], 1 the angle atan2(q[iq + 1], q[iq]) of a
    /// continuous joint, 2 the list q[iq + offsets[k]] (a quaternion w first).
    using JointField = std::tuple<std::string, int, int, std::vector<int>>;

    py::dict jointValues(const Eigen::VectorXd & q) const
    {
      py::dict out;
      for (const JointField & field : joints_)
      {
        const auto & [name, iq, kind, offsets] = field;
        if (kind == 0)
          out[py::str(name)] = q[iq];
        else if (kind == 1)
          out[py::str(name)] = std::atan2(q[iq + 1], q[iq]);
        else
        {
          py::list values;
          for (const int k : offsets)
            values.append(q[iq + k]);
          out[py::str(name)] = values;
        }
      }
      return out;
    }

    py::list jointNames(const std::vector<pinocchio::JointIndex> & joints) const
    {
      py::list out;
      for (const pinocchio::JointIndex j : joints)
        out.append(model_.names[j]);
      return out;
    }

    py::object model_obj_; // keeps model_ alive
    const pinocchio::Model & model_;
    std::unique_ptr<ForceElements> elements_;
    std::unique_ptr<LoopConstraints> loops_;
    std::unique_ptr<JointStops> stops_;
    std::unique_ptr<GroundContacts> contacts_;
    Solver solver_;
    py::tuple equal_limits_, unapplied_limits_;
    std::vector<JointField> joints_;
  };

  const char * kindName(SettingKind kind)
  {
    switch (kind)
    {
    case SettingKind::Number:
      return "number";
    case SettingKind::Integer:
      return "integer";
    case SettingKind::Switch:
      return "switch";
    case SettingKind::AutoNumber:
      return "auto_number";
    case SettingKind::AutoSwitch:
      return "auto_switch";
    case SettingKind::Choice:
      return "choice";
    }
    return "unknown";
  }

  // A setting's value as Python sees it: 'auto' for an AutoNumber at 0, the energy by name.
  py::object getSetting(const SettingField & field, const Settings & s)
  {
    return std::visit(
      [&](auto member) -> py::object {
        const auto value = s.*member;
        using T = std::decay_t<decltype(value)>;
        if constexpr (std::is_same_v<T, EnergyMeasure>)
          return py::str(toString(value));
        else if constexpr (std::is_same_v<T, Toggle>)
          return value == Toggle::Auto ? py::object(py::str("auto"))
                                       : py::object(py::bool_(value == Toggle::On));
        else if constexpr (std::is_same_v<T, double>)
          return field.kind == SettingKind::AutoNumber ? autoOrNumber(value)
                                                       : py::object(py::float_(value));
        else
          return py::cast(value);
      },
      field.member);
  }

  // Set a setting from Python: an AutoNumber takes 'auto' or a number its rule accepts (checked
  // here, as 0 would mean 'auto'); the others take their type, checked by checkSettings.
  void setSetting(const SettingField & field, Settings & s, const py::object & value)
  {
    std::visit(
      [&](auto member) {
        using T = std::decay_t<decltype(s.*member)>;
        if constexpr (std::is_same_v<T, EnergyMeasure>)
          s.*member = energyMeasureFromString(value.cast<std::string>());
        else if constexpr (std::is_same_v<T, Toggle>)
          s.*member = parseToggle(value, field.name, field.expected);
        else if constexpr (std::is_same_v<T, double>)
          s.*member = field.kind == SettingKind::AutoNumber
                        ? parseAutoOrNumber(value, field.name, field.expected, field.accepts)
                        : value.cast<double>();
        else
          s.*member = value.cast<T>();
      },
      field.member);
  }

  // Settings: one property per field of settingFields(), with its help as the docstring; the
  // list itself as Settings.fields() for the Python layer (types, stubs, command-line flags).
  void bindSettings(py::module_ & m)
  {
    py::class_<Settings> settings(
      m, "Settings", "Solver settings (inputs only; see pinsettle.Settings).");
    settings.def(py::init<>()).def(py::init<const Settings &>(), py::arg("other"));
    for (const SettingField & field : settingFields())
      settings.def_property(
        field.name, py::cpp_function([&field](const Settings & s) { return getSetting(field, s); }),
        py::cpp_function(
          [&field](Settings & s, const py::object & value) { setSetting(field, s, value); }),
        field.help);
    settings
      .def_property_readonly(
        "effective_dt_safety", &effectiveDtSafety,
        "The fraction dt='auto' uses: dt_safety, or for 'auto' that of the backtrack setting.")
      .def_property_readonly(
        "effective_dt_growth", &effectiveDtGrowth,
        "The growth dt='auto' uses: dt_growth, or for 'auto' that of the other settings.")
      .def("check", &checkSettings, "Raise ValueError naming the first invalid setting.")
      .def_static(
        "fields",
        []() {
          const Settings defaults;
          py::list out;
          for (const SettingField & field : settingFields())
          {
            py::dict d;
            d["name"] = field.name;
            d["kind"] = kindName(field.kind);
            d["expected"] = field.expected;
            d["help"] = field.help;
            d["default"] = getSetting(field, defaults);
            d["command_line"] = field.command_line;
            out.append(d);
          }
          return out;
        },
        "Every setting, declared once: name, kind ('number', 'integer', 'switch', "
        "'auto_number', 'auto_switch', 'choice'), what a value must be, its help, its default "
        "and whether the command line has a flag for it.");
  }

  // The solver and the stops it applies.
  void bindSolve(py::module_ & m)
  {
    py::class_<BoundSolver>(
      m, "Solver",
      "A kinetic-damping solver for one model and what the scene adds to it (force elements, "
      "loop closures, joint stops: None for none), reusable across solves.")
      .def(
        py::init<
          const py::object &, const py::object &, const py::object &, const py::object &,
          const py::object &, const py::object &>(),
        py::arg("model"), py::arg("elements") = py::none(), py::arg("loops") = py::none(),
        py::arg("stops") = py::none(), py::arg("joints") = py::none(),
        py::arg("contacts") = py::none(),
        "joints: how each joint's value is read from q, [(name, index in q, kind, offsets)] "
        "(kind 0 q[i], 1 atan2(q[i + 1], q[i]), 2 [q[i + k] for k in offsets]), or None for "
        "a result without the joints' values. contacts: ground planes and contact points, "
        "([(name, point, normal, friction)], [(name, joint index, position in the joint's "
        "frame, radius)]), or None.")
      .def(
        "solve", &BoundSolver::solve, py::arg("q0"), py::arg("v0"), py::arg("settings"),
        py::arg("callback") = py::none(), py::arg("progress") = py::none(),
        "Settle from (q0, v0): a dict of the result's fields (settings: a pinsettle Settings, "
        "given back in the dict). Ctrl-C or a callback returning True ends the run as "
        "'aborted'.")
      .def_property_readonly("model", &BoundSolver::model)
      .def_property_readonly("equal_limits", &BoundSolver::equalLimits)
      .def_property_readonly("unapplied_limits", &BoundSolver::unappliedLimits);

    m.def(
      "joint_stops",
      [](const py::object & model_obj, const py::object & spec) {
        const pinocchio::Model & model = modelFrom(model_obj);
        const std::unique_ptr<JointStops> stops = stopsFrom(model, spec);
        py::dict out;
        py::list list, equal, unapplied;
        if (stops)
        {
          for (const JointStops::Stop & s : stops->stops())
            list.append(py::make_tuple(model.names[s.joint], s.iq, s.iv, s.lower, s.upper));
          for (const pinocchio::JointIndex j : stops->equalLimitJoints())
            equal.append(model.names[j]);
          for (const pinocchio::JointIndex j : stops->unappliedLimitJoints())
            unapplied.append(model.names[j]);
        }
        out["stops"] = list;
        out["equal_limits"] = equal;
        out["unapplied_limits"] = unapplied;
        return out;
      },
      py::arg("model"), py::arg("stops"),
      "The stops the solver applies: (joint, index in q, index in v, lower, upper) for each "
      "joint with one, the joints whose equal model limits were taken as no stop, and the joints "
      "of several configuration entries whose model limits no stop applies.");
  }

  // What a model's pinocchio::Data takes, checked before one is made (model-checks.hpp).
  void bindMemoryTools(py::module_ & m)
  {
    m.def(
      "data_memory",
      [](const py::object & model_obj) { return computeDataMemory(supportedModel(model_obj)); },
      py::arg("model"),
      "Bytes one pinocchio.Data of the model takes (computeDataMemory): a Solver holds one.");

    m.def(
      "check_data_memory",
      [](const py::object & model_obj, int count, const std::string & what) {
        checkDataMemory(supportedModel(model_obj), count, what.c_str());
      },
      py::arg("model"), py::arg("count"), py::arg("what"),
      "Raise MemoryLimitError (a MemoryError) where count pinocchio.Data of the model would not "
      "fit in the memory available (checkDataMemory).");
  }

  // Helpers on a model: its kinetic energies, its mimic joints released.
  void bindModelTools(py::module_ & m)
  {
    m.def(
      "joint_layout",
      [](const py::object & model_obj) {
        const pinocchio::Model & model = modelFrom(model_obj);
        py::list names, idx_qs, nqs, nvs;
        for (pinocchio::JointIndex j = 0; j < static_cast<pinocchio::JointIndex>(model.njoints);
             ++j)
        {
          names.append(model.names[j]);
          idx_qs.append(model.idx_qs[j]);
          nqs.append(model.nqs[j]);
          nvs.append(model.nvs[j]);
        }
        return py::make_tuple(names, idx_qs, nqs, nvs);
      },
      py::arg("model"),
      "The joints' names, idx_qs, nqs and nvs as lists, in one call (reading each of the "
      "model's vectors from Python copies it).");

    m.def(
      "kinetic_energies",
      [](const py::object & model_obj, const Eigen::VectorXd & q, const Eigen::VectorXd & v) {
        const pinocchio::Model & model = modelFrom(model_obj);
        checkConfiguration(model, q, "q");
        checkVelocity(model, v, "v");
        pinocchio::Data data = makeData(model, "kinetic_energies");
        return computeKineticEnergies(model, data, q, v);
      },
      py::arg("model"), py::arg("q"), py::arg("v"));

    m.def(
      "release_mimic",
      [](const py::object & model_obj) {
        bp::extract<pinocchio::Model &> model(model_obj.ptr());
        if (!model.check())
          throw py::type_error("model must be a pinocchio.Model");
        std::vector<MimicJoint> mimics;
        pinocchio::Model released = releaseMimicJoints(model(), mimics);
        checkSupportedModel(released);
        py::list couplings;
        for (const MimicJoint & m : mimics)
          couplings.append(py::make_tuple(m.follower, m.leader, m.multiplier, m.offset));
        // A pinocchio.Model of Pinocchio's own bindings (Boost.Python owns the copy).
        const bp::object out(released);
        return py::make_tuple(py::reinterpret_borrow<py::object>(out.ptr()), couplings);
      },
      py::arg("model"),
      "The model with its mimic joints made ordinary joints, and the couplings [(follower, leader, "
      "multiplier, offset)] that hold them (joint indices, the same in both models).");
  }

  // Evaluations of a rest at one configuration: stiffness and verdict, static force.
  void bindEvaluations(py::module_ & m)
  {
    m.def(
      "stiffness",
      [](
        const py::object & model_obj, const Eigen::VectorXd & q, const py::object & spec,
        const py::object & loops, const py::object & stops) {
        Evaluation at = evaluationAt(model_obj, q, spec, loops, stops);
        const ConstraintSet constraints(at.model, at.loops.get(), at.stops.get());
        const StabilityReport report = constraints.assessStability(at.data, q, at.elements.get());
        py::dict out;
        out["stiffness_matrix"] = report.stiffness;
        out["verdict"] = toString(report.verdict);
        out["min_eigenvalue"] = report.min_eigenvalue;
        out["neutral_directions"] = report.neutral_directions;
        out["tolerance"] = report.tolerance;
        out["eigenvalues"] = report.eigenvalues;
        out["softest_direction"] = report.softest_direction;
        out["basis"] = report.basis;
        if (at.stops)
        {
          const Eigen::VectorXd tau = constraints.computeStaticForce(at.data, q, at.elements.get());
          Result rest;
          constraints.describeRest(at.data, q, tau, rest);
          out["stop_contacts"] = stopContactsToList(at.model, rest.stop_contacts);
          out["stop_residual"] = constraints.computeResidual(at.data, q, tau);
        }
        return out;
      },
      py::arg("model"), py::arg("q"), py::arg("elements") = py::none(),
      py::arg("loops") = py::none(), py::arg("stops") = py::none());

    m.def(
      "static_force",
      [](
        const py::object & model_obj, const Eigen::VectorXd & q, const py::object & spec,
        const py::object & loops) {
        Evaluation at = evaluationAt(model_obj, q, spec, loops);
        const ConstraintSet constraints(at.model, at.loops.get(), nullptr);
        return constraints.computeStaticForce(at.data, q, at.elements.get());
      },
      py::arg("model"), py::arg("q"), py::arg("elements") = py::none(),
      py::arg("loops") = py::none());
  }

  // The loops at one configuration, the start moved onto them, the time scale.
  void bindLoopTools(py::module_ & m)
  {
    m.def(
      "loops",
      [](const py::object & model_obj, const Eigen::VectorXd & q, const py::object & loops) {
        Evaluation at = evaluationAt(model_obj, q, py::none(), loops);
        py::dict out;
        if (!at.loops)
          throw std::invalid_argument("loops: none given");
        const LoopMotion motion = computeLoopMotion(at.model, at.data, *at.loops, q);
        out["error"] = computeLoopError(at.model, at.data, *at.loops, q);
        out["jacobian"] = computeLoopJacobian(at.model, at.data, *at.loops, q);
        out["rank"] = motion.rank;
        out["basis"] = motion.basis;
        return out;
      },
      py::arg("model"), py::arg("q"), py::arg("loops"),
      "Loop errors (m or rad), their Jacobian, its rank and the allowed motions at q.");

    m.def(
      "assemble_loops",
      [](const py::object & model_obj, const Eigen::VectorXd & q, const py::object & loops) {
        Evaluation at = evaluationAt(model_obj, q, py::none(), loops);
        Eigen::VectorXd out = q;
        pinocchio::normalize(at.model, out);
        double moved = 0.;
        if (at.loops)
          moved = assembleLoops(at.model, at.data, *at.loops, out);
        return py::make_tuple(out, moved);
      },
      py::arg("model"), py::arg("q"), py::arg("loops"),
      "q moved onto the loops (Gauss-Newton) and how far it moved; ValueError if it cannot be.");

    m.def(
      "time_scale",
      [](
        const py::object & model_obj, const Eigen::VectorXd & q, const py::object & spec,
        bool scale_stiff_modes, const py::object & loops) {
        Evaluation at = evaluationAt(model_obj, q, spec, loops);
        const TimeScale scale =
          at.loops ? computeTimeScale(at.model, at.data, *at.loops, q, at.elements.get())
                   : computeTimeScale(at.model, at.data, q, at.elements.get(), scale_stiff_modes);
        py::dict out;
        out["omega_max"] = scale.omega_max;
        out["omega_unscaled"] = scale.omega_unscaled;
        out["scaled_modes"] = static_cast<int>(scale.stiff_masses.size());
        out["damping_rate"] = scale.damping_rate;
        out["critical_step"] = scale.critical_step;
        return out;
      },
      py::arg("model"), py::arg("q"), py::arg("elements") = py::none(),
      py::arg("scale_stiff_modes") = false, py::arg("loops") = py::none());
  }

} // namespace

PYBIND11_MODULE(_core, m)
{
  m.doc() = "pinsettle C++ core: kinetic-damping static equilibrium on Pinocchio's ABA";
  // Registers the Boost.Python converters of pinocchio.Model.
  py::module_::import("pinocchio");
  // pybind11 finds numpy's C API (and parses numpy's version) on the first array it makes:
  // 1 ms, done here at import rather than in a user's first solve.
  (void)py::array_t<double>(0);
  // A model too large for the machine's memory: a MemoryError that says how much it needs.
  py::register_exception<pinsettle::MemoryLimitError>(m, "MemoryLimitError", PyExc_MemoryError);
  bindSettings(m);
  bindSolve(m);
  bindModelTools(m);
  bindMemoryTools(m);
  bindEvaluations(m);
  bindLoopTools(m);
}
