//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/model-checks.hpp"

#include <pinocchio/multibody.hpp>

#include <unistd.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pinsettle
{

  namespace
  {

    // Joint types of Pinocchio 4.1's JointCollectionDefault that aba, rnea, crba, the gravity
    // derivatives, constraintDynamics and integrate all support (composites are checked joint by
    // joint). A type missing here (a new one) is refused until it has been tried.
    bool isKnownJointType(const std::string & type)
    {
      static const char * const known[] = {
        "JointModelRX",
        "JointModelRY",
        "JointModelRZ",
        "JointModelFreeFlyer",
        "JointModelPlanar",
        "JointModelRevoluteUnaligned",
        "JointModelSpherical",
        "JointModelSphericalZYX",
        "JointModelEllipsoid",
        "JointModelPX",
        "JointModelPY",
        "JointModelPZ",
        "JointModelPrismaticUnaligned",
        "JointModelTranslation",
        "JointModelRUBX",
        "JointModelRUBY",
        "JointModelRUBZ",
        "JointModelRevoluteUnboundedUnaligned",
        "JointModelHX",
        "JointModelHY",
        "JointModelHZ",
        "JointModelHelicalUnaligned",
        "JointModelUniversal",
        "JointModelComposite"};
      return std::find(std::begin(known), std::end(known), type) != std::end(known);
    }

    std::string jointName(const pinocchio::Model & model, std::size_t j)
    {
      std::ostringstream out;
      if (j < model.names.size())
        out << "'" << model.names[j] << "'";
      else
        out << "number " << j;
      return out.str();
    }

    [[noreturn]] void refuse(const pinocchio::Model & model, std::size_t j, const std::string & why)
    {
      throw std::invalid_argument(
        "model: joint " + jointName(model, j) + " (index " + std::to_string(j) + ") " + why);
    }

    void refuseMimic(
      const pinocchio::Model & model, std::size_t j, const pinocchio::JointModelMimic & mimic)
    {
      const std::size_t leader = mimic.jmodel().id();
      const std::string follower = j < model.names.size() ? model.names[j] : std::to_string(j);
      const std::string leading =
        leader < model.names.size() ? model.names[leader] : std::to_string(leader);
      std::ostringstream why;
      why << "is a mimic joint of '" << leading
          << "': it couples q_follower = multiplier * q_leader + offset (here q[" << follower
          << "] = " << mimic.scaling() << " * q[" << leading << "] + " << mimic.offset()
          << "), which pinocchio::aba, the solver's forward dynamics, does not support. "
             "pinsettle.solve, assess_stability, static_force and Scene take such a model and "
             "hold the coupling as a constraint (in C++: releaseMimicJoints, then "
             "LoopConstraints::addCoupling); this function does not. Load the URDF with "
             "mimic=False (pinocchio.buildModelFromUrdf(path, mimic=False), Pinocchio's "
             "default) to ignore the <mimic> tag as Pinocchio does: the joint then moves on its "
             "own";
      refuse(model, j, why.str());
    }

    std::string vectorText(const Eigen::Vector3d & v)
    {
      std::ostringstream out;
      out.precision(17);
      out << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
      return out.str();
    }

    // A joint about or along an axis takes it to be a unit vector (Pinocchio asserts so only in
    // debug builds): a URDF's <axis xyz="0 0 0"> stays zero after Pinocchio's parser normalizes
    // the others, and the joint's "rotation" is then cos(q) times the identity, no motion a body
    // can make. Same precision as Pinocchio's check (Eigen's isUnitary).
    void checkAxes(
      const pinocchio::Model & model,
      std::size_t j,
      const pinocchio::JointModel::JointModelVariant & variant)
    {
      auto unit = [&](const Eigen::Vector3d & axis, const char * which) {
        if (!axis.allFinite() || !axis.isUnitary())
          refuse(
            model, j,
            std::string("has ") + which + " " + vectorText(axis)
              + ", not a unit vector: its motion is no rotation about or translation along an "
                "axis (a URDF <axis xyz=\"0 0 0\">?)");
      };
      if (const auto * r = boost::get<pinocchio::JointModelRevoluteUnaligned>(&variant))
        unit(r->axis, "the axis");
      else if (
        const auto * u = boost::get<pinocchio::JointModelRevoluteUnboundedUnaligned>(&variant))
        unit(u->axis, "the axis");
      else if (const auto * p = boost::get<pinocchio::JointModelPrismaticUnaligned>(&variant))
        unit(p->axis, "the axis");
      else if (const auto * h = boost::get<pinocchio::JointModelHelicalUnaligned>(&variant))
        unit(h->axis, "the axis");
      else if (const auto * universal = boost::get<pinocchio::JointModelUniversal>(&variant))
      {
        unit(universal->axis1, "the first axis");
        unit(universal->axis2, "the second axis");
        if (std::abs(universal->axis1.dot(universal->axis2)) > 1e-12)
          refuse(
            model, j,
            "is a universal joint whose axes " + vectorText(universal->axis1) + " and "
              + vectorText(universal->axis2) + " are not orthogonal");
      }
    }

    // A joint's own type, then those inside a composite.
    void checkJoint(
      const pinocchio::Model & model,
      std::size_t j,
      const pinocchio::JointModel & jmodel,
      bool part_of_composite = false)
    {
      const pinocchio::JointModel::JointModelVariant & variant = jmodel.toVariant();
      if (const auto * mimic = boost::get<pinocchio::JointModelMimic>(&variant))
        refuseMimic(model, j, *mimic);
      const std::string type = jmodel.shortname();
      if (!isKnownJointType(type))
        refuse(
          model, j,
          (part_of_composite ? "is a composite joint with a part of type " : "is of type ") + type
            + ", which pinsettle does not know: it has not been tried with the algorithms "
              "pinsettle runs on Pinocchio 4.1");
      checkAxes(model, j, variant);
      if (const auto * composite = boost::get<pinocchio::JointModelComposite>(&variant))
        for (const pinocchio::JointModel & part : composite->joints)
          checkJoint(model, j, part, true);
    }

    // One of the model's per-joint tables: its name (in the message), its length and whether
    // that is the number of joints.
    struct TableSize
    {
      const char * table;
      std::size_t size;
      bool agrees;
    };

    TableSize listSize(const char * table, std::size_t size, std::size_t n)
    {
      return {table, size, size == n};
    }

    // Start indices and lengths are read together: the pair agrees when both do; the shorter
    // is the one named.
    TableSize pairSize(const char * table, std::size_t starts, std::size_t lengths, std::size_t n)
    {
      return {table, std::min(starts, lengths), starts == n && lengths == n};
    }

    TableSize njointsSize(const pinocchio::Model & model, std::size_t n)
    {
      return {
        "njoints", static_cast<std::size_t>(model.njoints),
        n != 0 && model.njoints == static_cast<int>(n)};
    }

    void checkTableSizes(const pinocchio::Model & model)
    {
      const std::size_t n = model.joints.size();
      // In this order: the first that disagrees is the one reported.
      const TableSize tables[] = {
        njointsSize(model, n),
        listSize("parents", model.parents.size(), n),
        listSize("names", model.names.size(), n),
        listSize("jointPlacements", model.jointPlacements.size(), n),
        listSize("inertias", model.inertias.size(), n),
        pairSize("idx_qs/nqs", model.idx_qs.size(), model.nqs.size(), n),
        pairSize("idx_vs/nvs", model.idx_vs.size(), model.nvs.size(), n),
      };
      for (const TableSize & t : tables)
      {
        if (t.agrees)
          continue;
        std::ostringstream msg;
        msg << "model: its tables disagree: " << n << " joints (with the universe) but " << t.size
            << " entries in " << t.table << "; the model was changed by hand after it was built";
        throw std::invalid_argument(msg.str());
      }
    }

    void checkNoMimicSpace(const pinocchio::Model & model)
    {
      if (model.nv != model.nvExtended)
        throw std::invalid_argument(
          "model: its extended velocity space (nvExtended " + std::to_string(model.nvExtended)
          + ") differs from its velocity space (nv " + std::to_string(model.nv)
          + "): a joint mimics another, which pinocchio::aba does not support (releaseMimicJoints "
            "makes it an ordinary joint to couple as a constraint)");
    }

    // Joint j's indices in q and v, as the joint and the model's tables give them, are where the
    // joints before it end (iq, iv).
    bool indicesFollow(const pinocchio::Model & model, std::size_t j, int iq, int iv)
    {
      const pinocchio::JointModel & jmodel = model.joints[j];
      const bool q_follows =
        jmodel.idx_q() == iq && jmodel.nq() == model.nqs[j] && model.idx_qs[j] == iq;
      const bool v_follows =
        jmodel.idx_v() == iv && jmodel.nv() == model.nvs[j] && model.idx_vs[j] == iv;
      return q_follows && v_follows;
    }

    // Each joint's parent comes before it and its q and v segments follow the previous joint's,
    // and together they tile q and v.
    void checkJointOrderAndIndices(const pinocchio::Model & model)
    {
      int iq = 0, iv = 0;
      for (std::size_t j = 1; j < model.joints.size(); ++j)
      {
        if (model.parents[j] >= j)
          refuse(
            model, j,
            "has parent index " + std::to_string(model.parents[j])
              + ", not before it: the joints are not a tree in order");
        if (!indicesFollow(model, j, iq, iv))
          refuse(
            model, j,
            "has configuration or velocity indices that do not follow the joint before it (the "
            "model was changed by hand after it was built)");
        iq += model.joints[j].nq();
        iv += model.joints[j].nv();
      }
      if (iq != model.nq || iv != model.nv)
        throw std::invalid_argument(
          "model: its joints span " + std::to_string(iq) + " configuration and "
          + std::to_string(iv) + " velocity entries, but nq = " + std::to_string(model.nq)
          + " and nv = " + std::to_string(model.nv));
    }

    // Tables of the model that Pinocchio's algorithms index without checking.
    void checkTables(const pinocchio::Model & model)
    {
      checkTableSizes(model);
      checkNoMimicSpace(model);
      checkJointOrderAndIndices(model);
    }

    // The bodies (BODY frames) joint j moves directly, named for a message: "body 'a'" or
    // "bodies 'a', 'b'" (their inertias are summed into the joint's), else the joint's.
    std::string bodiesOf(const pinocchio::Model & model, std::size_t j)
    {
      std::vector<std::string> names;
      for (const pinocchio::Frame & frame : model.frames)
        if (frame.type == pinocchio::BODY && frame.parentJoint == j)
          names.push_back("'" + frame.name + "'");
      if (names.empty())
        return "the body of joint " + jointName(model, j);
      std::string out = names.size() == 1 ? "body " : "bodies ";
      for (std::size_t k = 0; k < names.size(); ++k)
        out += (k > 0 ? ", " : "") + names[k];
      return out + " (moved by joint " + jointName(model, j) + ")";
    }

    // What is wrong with a body's inertia, or empty: a mass that is negative or not finite, a
    // centre of mass or rotational inertia that is not finite, a rotational inertia about the
    // centre of mass that is not positive semidefinite (ABA would run on, with energies of
    // either sign: a URDF's mass of -2 ended in a step of 2.9e41 s, a Python model's converged).
    std::string inertiaFault(const pinocchio::Inertia & inertia)
    {
      std::ostringstream why;
      const Eigen::Matrix3d I = inertia.inertia().matrix();
      if (!std::isfinite(inertia.mass()) || inertia.mass() < 0.)
        why << "has mass " << inertia.mass() << " kg; a mass must be finite and >= 0";
      else if (!inertia.lever().allFinite() || !I.allFinite())
        why << "has a centre of mass or rotational inertia that is not finite";
      else
      {
        const Eigen::Vector3d moments =
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(I, Eigen::EigenvaluesOnly).eigenvalues();
        if (moments[0] < -1e-9 * std::max(moments.cwiseAbs().maxCoeff(), 1e-12))
          why << "has a rotational inertia with principal moments (" << moments.transpose()
              << ") kg m^2 about its centre of mass; an inertia must be positive semidefinite";
      }
      return why.str();
    }

    void checkInertias(const pinocchio::Model & model)
    {
      for (std::size_t j = 1; j < model.inertias.size(); ++j)
      {
        const std::string why = inertiaFault(model.inertias[j]);
        if (!why.empty())
          throw std::invalid_argument("model: " + bodiesOf(model, j) + " " + why);
      }
    }

    // Pinocchio's algorithms that work on subtrees (crba, computeMinverse, the gravity
    // derivatives) take a joint's descendants to be the joints right after it: depth-first
    // order, as the URDF parser adds them. A model built by hand in another order gets a wrong
    // mass matrix from crba (aba and rnea, which only follow the parents, stay right).
    // Depth-first: the parent of joint j is joint j - 1 or one of its ancestors.
    void checkDepthFirstOrder(const pinocchio::Model & model)
    {
      for (std::size_t j = 2; j < model.joints.size(); ++j)
      {
        const std::size_t parent = model.parents[j];
        std::size_t a = j - 1;
        while (a != 0 && a != parent)
          a = model.parents[a];
        if (a != parent)
          refuse(
            model, j,
            "hangs from " + jointName(model, parent) + " but comes after " + jointName(model, j - 1)
              + ", which is not in that joint's subtree: the joints are not in depth-first order, "
                "which Pinocchio's crba and derivatives need (they take a joint's subtree to be "
                "the joints right after it; their mass matrix would be wrong). Add each joint's "
                "descendants before the next branch, as Pinocchio's URDF parser does");
      }
    }

    // The per-joint limits and properties a released model keeps, by configuration entry and
    // by velocity entry.
    using ModelVector = pinocchio::Model::VectorXs pinocchio::Model::*;
    constexpr ModelVector kConfigurationProperties[] = {
      &pinocchio::Model::lowerPositionLimit, &pinocchio::Model::upperPositionLimit};
    constexpr ModelVector kVelocityProperties[] = {
      &pinocchio::Model::lowerEffortLimit,   &pinocchio::Model::upperEffortLimit,
      &pinocchio::Model::lowerVelocityLimit, &pinocchio::Model::upperVelocityLimit,
      &pinocchio::Model::armature,           &pinocchio::Model::rotorInertia,
      &pinocchio::Model::rotorGearRatio,     &pinocchio::Model::damping};

    // The tables releaseMimicJoints reads for every joint.
    bool joinedTablesAgree(const pinocchio::Model & model)
    {
      const std::size_t n = model.joints.size();
      return model.parents.size() == n && model.names.size() == n
             && model.jointPlacements.size() == n && model.inertias.size() == n;
    }

    // Joint j as it is, with its limits and properties (each joint's own segment: the indices
    // shift after a follower).
    void copyJoint(const pinocchio::Model & model, std::size_t j, pinocchio::Model & out)
    {
      const pinocchio::JointModel & jmodel = model.joints[j];
      const pinocchio::JointIndex id =
        out.addJoint(model.parents[j], jmodel, model.jointPlacements[j], model.names[j]);
      const pinocchio::JointModel & copy = out.joints[id];
      for (const ModelVector property : kConfigurationProperties)
        copy.jointConfigSelector(out.*property) = jmodel.jointConfigSelector(model.*property);
      for (const ModelVector property : kVelocityProperties)
        copy.jointVelocitySelector(out.*property) = jmodel.jointVelocitySelector(model.*property);
    }

    // A follower pinsettle can couple back: a 1-DoF joint following an ordinary joint before it.
    void checkFollower(
      const pinocchio::Model & model, std::size_t j, const pinocchio::JointModel & own)
    {
      const pinocchio::JointIndex leader = own.id();
      if (leader == 0 || leader >= j)
        refuse(model, j, "is a mimic joint of a joint that does not come before it");
      if (boost::get<pinocchio::JointModelMimic>(&model.joints[leader].toVariant()) != nullptr)
        refuse(
          model, j, "is a mimic joint of another mimic joint (" + jointName(model, leader) + ")");
      if (own.nq() != 1 || own.nv() != 1)
        refuse(
          model, j,
          "is a mimic joint of type " + own.shortname() + " (" + std::to_string(own.nq())
            + " configuration entries, " + std::to_string(own.nv())
            + " velocities); pinsettle couples 1-DoF joints with one of each (revolute, "
              "prismatic, helical)");
    }

    // Follower j as an ordinary joint of its own type and axis, without the mimic model's
    // limits (it keeps none for a follower); returns its coupling.
    MimicJoint releaseFollower(
      const pinocchio::Model & model,
      std::size_t j,
      const pinocchio::JointModelMimic & mimic,
      pinocchio::Model & out)
    {
      // The follower's own joint (type and axis); its id is the leader's.
      const pinocchio::JointModel own = mimic.jmodel();
      checkFollower(model, j, own);
      const pinocchio::JointIndex id =
        out.addJoint(model.parents[j], own, model.jointPlacements[j], model.names[j]);
      return MimicJoint{id, own.id(), mimic.scaling(), mimic.offset()};
    }
  } // namespace

  pinocchio::Model releaseMimicJoints(
    const pinocchio::Model & model, std::vector<MimicJoint> & mimics)
  {
    mimics.clear();
    if (!joinedTablesAgree(model))
      checkTables(model); // names the table that disagrees
    pinocchio::Model out;
    out.name = model.name;
    out.gravity = model.gravity;
    for (std::size_t j = 1; j < model.joints.size(); ++j)
    {
      const auto * mimic = boost::get<pinocchio::JointModelMimic>(&model.joints[j].toVariant());
      if (mimic == nullptr)
        copyJoint(model, j, out);
      else
        mimics.push_back(releaseFollower(model, j, *mimic, out));
      out.appendBodyToJoint(
        static_cast<pinocchio::JointIndex>(j), model.inertias[j], pinocchio::SE3::Identity());
    }
    // Frames keep their indices: the joints do.
    for (std::size_t f = 1; f < model.frames.size(); ++f)
      out.addFrame(model.frames[f], false);
    return out;
  }

  void checkSupportedModel(const pinocchio::Model & model)
  {
    // Mimic joints first: the most common case, with the most useful message.
    for (std::size_t j = 1; j < model.joints.size(); ++j)
      checkJoint(model, j, model.joints[j]);
    checkTables(model);
    checkDepthFirstOrder(model);
    checkInertias(model);
  }

  std::size_t computeDataMemory(const pinocchio::Model & model)
  {
    const double nv = static_cast<double>(model.nv);
    const double joints = static_cast<double>(model.njoints);
    // The tensors; about 30 nv x nv matrices (M, Minv, C, the first-order derivatives, the
    // kinematic Hessians' 6 nv^2, ...); per joint its spatial blocks. Measured by the resident
    // memory a Solver adds (tests/test_resources.py): 262 MB at nv = 200 against 267 counted.
    const double bytes = 8. * (4. * nv * nv * nv + 30. * nv * nv) + 8192. * joints;
    return static_cast<std::size_t>(bytes);
  }

  std::size_t availableMemory()
  {
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    std::size_t kb = 0;
    std::string unit;
    while (meminfo >> key >> kb >> unit)
      if (key == "MemAvailable:")
        return kb * 1024;
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? static_cast<std::size_t>(pages) * static_cast<std::size_t>(page)
                                 : 0;
  }

  bool fitsInMemory(const pinocchio::Model & model, int count)
  {
    // Pinocchio 4.1's Data constructor allocates and zeroes its four nv^3 tensors whichever
    // algorithm runs: 32 GB for nv = 1000, where the allocation fails (std::bad_alloc) or, with
    // memory overcommitted, the zeroing wakes the kernel's OOM killer. Below kSmallData no
    // machine lacks the memory, and /proc is not read (a solve of a small model takes less
    // time than reading it).
    constexpr double kSmallData = 256. * 1024. * 1024.;
    const double need = static_cast<double>(count) * static_cast<double>(computeDataMemory(model));
    if (need <= kSmallData)
      return true;
    const double have = static_cast<double>(availableMemory());
    return have == 0. || need <= have;
  }

  void checkDataMemory(const pinocchio::Model & model, int count, const char * what)
  {
    if (fitsInMemory(model, count))
      return;
    const double need = static_cast<double>(count) * static_cast<double>(computeDataMemory(model));
    const double have = static_cast<double>(availableMemory()); // read again for the message
    std::ostringstream msg;
    msg.precision(3);
    msg << "the model is too large for this machine's memory: " << what << " needs ";
    if (count == 1)
      msg << "a pinocchio.Data of " << need / 1e9 << " GB";
    else
      msg << count << " pinocchio.Data objects of " << need / count / 1e9 << " GB each, "
          << need / 1e9 << " GB in all";
    msg << " (model.nv = " << model.nv
        << "; Pinocchio 4.1 keeps four nv x nv x nv tensors of second-order derivatives in every "
           "Data), and "
        << have / 1e9
        << " GB are available; a mechanism of this size needs a machine with more memory, or "
           "fewer degrees of freedom (lock joints that do not move)";
    throw MemoryLimitError(msg.str());
  }

  pinocchio::Data makeData(const pinocchio::Model & model, const char * what)
  {
    checkDataMemory(model, 1, what);
    return pinocchio::Data(model);
  }

} // namespace pinsettle
