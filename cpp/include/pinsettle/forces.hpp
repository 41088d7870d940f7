//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_forces_hpp__
#define __pinsettle_forces_hpp__

#include <pinocchio/multibody.hpp>

#include <limits>
#include <string>

namespace pinsettle
{

  typedef std::vector<pinocchio::Force> ForceVector;

  ///
  /// \brief Applied efforts acting on a mechanism besides gravity (springs, loads, ...).
  ///
  /// The solver calls computeForces once per step, before pinocchio::aba. A solve without a
  /// ForceModel computes nothing extra per step.
  ///
  class ForceModel
  {
  public:
    virtual ~ForceModel() = default;

    /// \brief Whether computeForces fills spatial forces; only then is aba called with fext.
    virtual bool hasExternalForces() const
    {
      return false;
    }

    /// \brief Whether the efforts depend on the velocity (dampers); only then does the automatic
    /// time step look at the damping matrix.
    virtual bool hasDamping() const
    {
      return false;
    }

    /// \brief Whether the model applies nothing; the solver then skips it altogether.
    virtual bool empty() const
    {
      return false;
    }

    ///
    /// \brief Whether the efforts may tie the subtree of joint root to the world: act on root's
    /// own coordinates, or change their net force on the subtree when it moves as a whole (a
    /// spring from it to the world or to another branch). Where they cannot, a root that
    /// translates freely under a net force falls for ever (explainFreeFall). True unless the
    /// model knows better.
    ///
    virtual bool tiesToWorld(
      const pinocchio::Model & /*model*/, pinocchio::JointIndex /*root*/) const
    {
      return true;
    }

    /// \brief Whether addStiffness gives the efforts' share of the stiffness in closed form;
    /// otherwise the stiffness takes it by central differences of computeForces.
    virtual bool hasClosedFormStiffness() const
    {
      return false;
    }

    ///
    /// \brief Add the efforts' share of the stiffness, -d applied / d q at (q, v = 0), to K.
    /// Called only when hasClosedFormStiffness() is true.
    ///
    /// \param[in] model The model of the mechanism.
    /// \param[in] data Scratch data of the model (its kinematic quantities are overwritten).
    /// \param[in] q The joint configuration (dim model.nq).
    /// \param[in,out] K Stiffness (dim model.nv x model.nv, N m/rad or N/m).
    ///
    virtual void addStiffness(
      const pinocchio::Model & /*model*/,
      pinocchio::Data & /*data*/,
      const Eigen::VectorXd & /*q*/,
      Eigen::MatrixXd & /*K*/) const
    {
    }

    ///
    /// \brief The work (J) the efforts do on a motion from q_from to q_to: the elastic energy
    /// the springs release plus the work of the constant loads. The dampers are left out (they
    /// only take energy away). The solver compares it with the energy a runaway released, to
    /// tell a mechanism that really falls from a time step too large for it.
    ///
    /// \param[in] model The model of the mechanism.
    /// \param[in] data Scratch data of the model (its kinematic quantities are overwritten).
    /// \param[in] q_from, q_to The configurations at the two ends (dim model.nq).
    /// \param[in] motion The net tangent motion from q_from to q_to, summed step by step (dim
    ///            model.nv, rad or m): a joint that turned several times has its whole angle.
    /// \return The work (J); NaN where the two ends and the net motion do not tell it (the
    ///         default; a constant torque on a body that turns in space).
    ///
    virtual double computeWork(
      const pinocchio::Model & /*model*/,
      pinocchio::Data & /*data*/,
      const Eigen::VectorXd & /*q_from*/,
      const Eigen::VectorXd & /*q_to*/,
      const Eigen::VectorXd & /*motion*/) const
    {
      return std::numeric_limits<double>::quiet_NaN();
    }

    ///
    /// \brief Add the applied efforts at the state (q, v).
    ///
    /// \param[in] model The model of the mechanism.
    /// \param[in] data Scratch data of the model (kinematic quantities may be stale).
    /// \param[in] q The joint configuration (dim model.nq).
    /// \param[in] v The joint velocity (dim model.nv).
    /// \param[in,out] tau Generalized efforts (dim model.nv, N m or N), zero on entry.
    /// \param[in,out] fext Spatial forces on each joint, expressed in the joint's local frame
    ///                (size model.njoints), zero on entry; only touched when
    ///                hasExternalForces() is true.
    ///
    virtual void computeForces(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      Eigen::VectorXd & tau,
      ForceVector & fext) const = 0;
  };

  ///
  /// \brief A constant generalized effort (a motor torque held fixed, a constant load on a
  /// joint).
  ///
  class ConstantGeneralizedForce : public ForceModel
  {
  public:
    /// \param[in] tau The constant effort (dim model.nv, N m or N).
    explicit ConstantGeneralizedForce(const Eigen::VectorXd & tau);

    /// A constant effort adds no stiffness.
    bool hasClosedFormStiffness() const override
    {
      return true;
    }

    void computeForces(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      Eigen::VectorXd & tau,
      ForceVector & fext) const override;

    const Eigen::VectorXd & effort() const
    {
      return tau_;
    }

    /// The effort's work on the net motion: constant in tangent coordinates, it does
    /// tau . dq on every step.
    double computeWork(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q_from,
      const Eigen::VectorXd & q_to,
      const Eigen::VectorXd & motion) const override;

    /// Only an effort on root's own coordinates: any other is a pair inside the subtree.
    bool tiesToWorld(const pinocchio::Model & model, pinocchio::JointIndex root) const override;

  private:
    Eigen::VectorXd tau_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_forces_hpp__
