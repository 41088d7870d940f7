//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_elements_hpp__
#define __pinsettle_elements_hpp__

#include "pinsettle/forces.hpp"

#include <vector>

namespace pinsettle
{

  /// \brief A spring-damper on a 1-DoF joint: tau = -stiffness (q - rest) - damping qdot.
  struct JointSpring
  {
    pinocchio::JointIndex joint;
    double stiffness; ///< N m/rad or N/m, >= 0.
    double rest;      ///< rad or m.
    double damping;   ///< N m s/rad or N s/m, >= 0.
  };

  /// \brief A point of a body: a point given in the frame of the joint that carries the body.
  struct Attachment
  {
    pinocchio::JointIndex joint; ///< 0 is the world.
    Eigen::Vector3d point;       ///< In the joint's frame (m).
  };

  ///
  /// \brief A straight spring-damper between two points: tension
  /// stiffness (|d| - rest_length) + damping d|d|/dt along d = b - a.
  ///
  struct PointSpring
  {
    Attachment a, b;
    double stiffness;   ///< N/m, >= 0.
    double rest_length; ///< m, >= 0.
    double damping;     ///< N s/m, >= 0.
  };

  /// \brief A constant effort on a joint (dim of the joint's velocity, N m or N).
  struct JointLoad
  {
    pinocchio::JointIndex joint;
    Eigen::VectorXd effort;
  };

  /// \brief A constant force and torque, world-aligned, applied at a point of a body.
  struct PointLoad
  {
    Attachment at;
    Eigen::Vector3d force;  ///< N, world axes.
    Eigen::Vector3d torque; ///< N m, world axes.
  };

  ///
  /// \brief The force elements of a scene: joint spring-dampers, point-to-point spring-dampers,
  /// constant joint efforts and constant point loads.
  ///
  /// Point elements act through the fext argument of pinocchio::aba (spatial forces on the two
  /// joints), so their cost is one forward kinematics pass plus O(1) per element, and no Jacobian
  /// is formed. Only the kinds present run: without point elements aba is called without fext
  /// and no kinematics pass is made.
  ///
  /// Elements are given by frame (a Pinocchio frame, e.g. a URDF link) and resolved to joints on
  /// insertion. The model must outlive the elements.
  ///
  class ForceElements : public ForceModel
  {
  public:
    explicit ForceElements(const pinocchio::Model & model);

    ///
    /// \brief Add a spring-damper on a 1-DoF joint (revolute, continuous, prismatic, helical).
    /// For a continuous joint the angle is atan2(sin, cos) and q - rest is wrapped to [-pi, pi].
    ///
    /// \throws std::invalid_argument for an unknown joint, a joint with nv != 1 or a negative or
    ///         non-finite coefficient.
    ///
    void addJointSpring(
      pinocchio::JointIndex joint, double stiffness, double rest = 0., double damping = 0.);

    ///
    /// \brief Add a straight spring-damper from point_a of frame_a to point_b of frame_b.
    ///
    /// \param[in] point_a The point in frame_a (m); frame 0 ("universe") is the world.
    ///
    void addPointSpring(
      pinocchio::FrameIndex frame_a,
      const Eigen::Vector3d & point_a,
      pinocchio::FrameIndex frame_b,
      const Eigen::Vector3d & point_b,
      double stiffness,
      double rest_length = 0.,
      double damping = 0.);

    /// \brief Add a constant effort on a joint (dim model.nvs[joint], N m or N).
    void addJointLoad(pinocchio::JointIndex joint, const Eigen::VectorXd & effort);

    /// \brief Add a constant world-aligned force (N) and torque (N m) at a point of a frame (m).
    void addPointLoad(
      pinocchio::FrameIndex frame,
      const Eigen::Vector3d & point,
      const Eigen::Vector3d & force,
      const Eigen::Vector3d & torque = Eigen::Vector3d::Zero());

    bool empty() const override
    {
      return joint_springs_.empty() && point_springs_.empty() && !has_joint_loads_
             && point_loads_.empty();
    }

    bool hasDamping() const override
    {
      return joint_damping_ || spring_damping_;
    }

    bool hasExternalForces() const override
    {
      return !point_springs_.empty() || !point_loads_.empty();
    }

    ///
    /// The stiffness in closed form: joint springs' k on the diagonal; a point spring's
    /// G^T K_c G (G the Jacobian of its span, K_c its axial and transverse stiffness) and, for
    /// every point element, the turning of the joints' axes under its world-fixed force. This
    /// holds where every joint that carries a point element moves by the exponential of its
    /// tangent directions (revolute, prismatic, helical, continuous, spherical, planar,
    /// translation, free-flyer); below a universal, ZYX-spherical, ellipsoid or composite joint
    /// the stiffness is differenced.
    ///
    bool hasClosedFormStiffness() const override
    {
      return !points_differenced_;
    }

    void addStiffness(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      Eigen::MatrixXd & K) const override;

    void computeForces(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      Eigen::VectorXd & tau,
      ForceVector & fext) const override;

    ///
    /// The springs' elastic energy, 1/2 k stretch^2, at q_from less at q_to; the joint loads'
    /// effort . motion; the point loads' force . the point's displacement. NaN with a point load
    /// that has a torque (its work depends on how the body turned on the way).
    ///
    double computeWork(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q_from,
      const Eigen::VectorXd & q_to,
      const Eigen::VectorXd & motion) const override;

    /// A joint spring or load on root, or a point spring with one end in root's subtree and the
    /// other outside it; point loads are constant world forces.
    bool tiesToWorld(const pinocchio::Model & model, pinocchio::JointIndex root) const override;

    const std::vector<JointSpring> & jointSprings() const
    {
      return joint_springs_;
    }
    const std::vector<PointSpring> & pointSprings() const
    {
      return point_springs_;
    }
    const std::vector<PointLoad> & pointLoads() const
    {
      return point_loads_;
    }
    /// \brief The sum of the constant joint efforts (dim model.nv).
    const Eigen::VectorXd & jointLoads() const
    {
      return joint_loads_;
    }

  private:
    // The point springs' elastic energy and the point loads' potential -force . point (J) at q.
    double pointEnergy(
      const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q) const;

    Attachment attach(
      pinocchio::FrameIndex frame, const Eigen::Vector3d & point, const char * what) const;

    const pinocchio::Model & model_;
    std::vector<JointSpring> joint_springs_;
    std::vector<PointSpring> point_springs_;
    std::vector<PointLoad> point_loads_;
    Eigen::VectorXd joint_loads_;
    bool has_joint_loads_ = false;
    bool points_differenced_ = false; // a point element below a joint with no closed form
    bool spring_damping_ = false;     // a point spring with damping needs body velocities
    bool joint_damping_ = false;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_elements_hpp__
