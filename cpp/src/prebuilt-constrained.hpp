//
// Copyright (c) 2026 pinsettle contributors
//
// Pinocchio's constrained dynamics through the explicit instantiations of pinocchio_default.
//

#ifndef __pinsettle_prebuilt_constrained_hpp__
#define __pinsettle_prebuilt_constrained_hpp__

#include <pinocchio/algorithm/proximal.hpp>
#include <pinocchio/constraints.hpp>
#include <pinocchio/multibody/data.hpp>
#include <pinocchio/multibody/model.hpp>

#include <vector>

// pinocchio::initConstraintDynamics and pinocchio::constraintDynamics are inline function
// templates: an `extern template` does not keep a translation unit that sees their definitions
// (pinocchio/algorithm/constrained-dynamics.hpp) from instantiating them again (C++17
// [temp.explicit]/10), and constraintDynamics was most of loops.cpp's compile (docs/
// install-time.md). Declared here exactly as Pinocchio 4.1 declares them (the same template
// parameters and return type, hence the same symbols), without their definitions, the calls
// below go to the instantiations that libpinocchio_default.so carries and exports for these
// argument types (nm -D). A translation unit including this header must not include
// constrained-dynamics.hpp; a call with other argument types fails to link.
namespace pinocchio
{
  template<
    typename Scalar,
    int Options,
    template<typename, int> class JointCollectionTpl,
    class ConstraintModel,
    class ConstraintModelAllocator,
    class ConstraintData,
    class ConstraintDataAllocator>
  void initConstraintDynamics(
    const ModelTpl<Scalar, Options, JointCollectionTpl> & model,
    DataTpl<Scalar, Options, JointCollectionTpl> & data,
    const std::vector<ConstraintModel, ConstraintModelAllocator> & contact_models,
    const std::vector<ConstraintData, ConstraintDataAllocator> & contact_datas);

  template<
    typename Scalar,
    int Options,
    template<typename, int> class JointCollectionTpl,
    typename ConfigVectorType,
    typename TangentVectorType1,
    typename TangentVectorType2,
    class ConstraintModelAllocator,
    class ConstraintDataAllocator>
  const typename DataTpl<Scalar, Options, JointCollectionTpl>::TangentVectorType &
  constraintDynamics(
    const ModelTpl<Scalar, Options, JointCollectionTpl> & model,
    DataTpl<Scalar, Options, JointCollectionTpl> & data,
    const Eigen::MatrixBase<ConfigVectorType> & q,
    const Eigen::MatrixBase<TangentVectorType1> & v,
    const Eigen::MatrixBase<TangentVectorType2> & tau,
    const std::vector<RigidConstraintModelTpl<Scalar, Options>, ConstraintModelAllocator> &
      contact_models,
    std::vector<RigidConstraintDataTpl<Scalar, Options>, ConstraintDataAllocator> & contact_datas,
    ProximalSettingsTpl<Scalar> & settings);
} // namespace pinocchio

namespace pinsettle
{
  namespace prebuilt
  {
    typedef std::vector<pinocchio::RigidConstraintModel> ConstraintModelVector;
    typedef std::vector<pinocchio::RigidConstraintData> ConstraintDataVector;

    /// \brief pinocchio::initConstraintDynamics (pinocchio_default's instantiation).
    inline void initConstraintDynamics(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const ConstraintModelVector & models,
      const ConstraintDataVector & datas)
    {
      pinocchio::initConstraintDynamics(model, data, models, datas);
    }

    /// \brief pinocchio::constraintDynamics with proximal settings (pinocchio_default's
    /// instantiation): the constrained joint acceleration, also in data.ddq.
    inline const Eigen::VectorXd & constraintDynamics(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const Eigen::VectorXd & tau,
      const ConstraintModelVector & models,
      ConstraintDataVector & datas,
      pinocchio::ProximalSettings & settings)
    {
      return pinocchio::constraintDynamics(model, data, q, v, tau, models, datas, settings);
    }
  } // namespace prebuilt
} // namespace pinsettle

#endif // ifndef __pinsettle_prebuilt_constrained_hpp__
