//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_loops_hpp__
#define __pinsettle_loops_hpp__

#include "pinsettle/forces.hpp"
#include "pinsettle/stability.hpp"
#include "pinsettle/stops.hpp"

#include <string>
#include <vector>

namespace pinsettle
{

  /// \brief What a loop holds together.
  enum class LoopKind
  {
    /// Two points coincide (3 equations): a spherical joint, or a pin joint in a plane.
    Point,
    /// Two frames coincide (6 equations): a weld.
    Frame
  };

  /// \brief snake_case name: "point", "frame".
  const char * toString(LoopKind kind);

  ///
  /// \brief A loop closure: the placement placement_a of joint_a's body and placement_b of
  /// joint_b's body are held together (their origins for LoopKind::Point, the whole frames for
  /// LoopKind::Frame).
  ///
  struct Loop
  {
    std::string name;
    pinocchio::JointIndex joint_a; ///< 0 is the world.
    pinocchio::SE3 placement_a;    ///< In joint_a's frame.
    pinocchio::JointIndex joint_b;
    pinocchio::SE3 placement_b;
    LoopKind kind;

    /// \brief Number of constraint equations: 3 or 6.
    int rows() const
    {
      return kind == LoopKind::Point ? 3 : 6;
    }
  };

  ///
  /// \brief A linear coupling of two 1-DoF joints, q[follower] = multiplier * q[leader] + offset
  /// (a URDF <mimic> tag): one constraint equation, error q_f - multiplier q_l - offset (rad or
  /// m), constant Jacobian row e_f - multiplier e_l.
  ///
  struct JointCoupling
  {
    std::string name;
    pinocchio::JointIndex follower;
    pinocchio::JointIndex leader;
    int iq_follower, iv_follower, iq_leader, iv_leader;
    double multiplier;
    double offset;
  };

  ///
  /// \brief The loop closures of a mechanism whose model is a tree (a four-bar, a slider-crank,
  /// a parallel gripper): the model describes the tree, these constraints close it; and the
  /// joint couplings of its mimic joints (JointCoupling), which every function below treats as
  /// more constraint equations.
  ///
  /// The constraint error of a loop is p_a - p_b for a point loop, and
  /// [p_a - p_b; log3(R_a R_b^T)] for a frame loop, in world axes (m and rad). Its Jacobian along
  /// the tangent directions of the configuration (those of pinocchio::integrate) is the relative
  /// velocity of the two points (and the relative angular velocity), world axes. Redundant
  /// equations (a planar four-bar closed by a 3-D point constraint) are allowed: every use goes
  /// through a rank-revealing decomposition.
  ///
  /// The model must outlive the constraints.
  ///
  class LoopConstraints
  {
  public:
    explicit LoopConstraints(const pinocchio::Model & model);

    ///
    /// \brief Close a loop between point_a of frame_a and point_b of frame_b.
    ///
    /// \param[in] point_a The point in frame_a (m); frame 0 ("universe") is the world. For a
    ///            frame loop the two frames, moved to their points, must coincide.
    /// \param[in] name How messages call it ("loop #1" when empty).
    /// \throws std::invalid_argument for an unknown frame, a non-finite point, or two frames on
    ///         the same body (such a loop holds nothing).
    ///
    void addLoop(
      pinocchio::FrameIndex frame_a,
      const Eigen::Vector3d & point_a,
      pinocchio::FrameIndex frame_b,
      const Eigen::Vector3d & point_b,
      LoopKind kind = LoopKind::Point,
      const std::string & name = std::string());

    ///
    /// \brief Couple two 1-DoF joints (revolute, prismatic, helical: one configuration entry
    /// and one velocity each): q[follower] = multiplier * q[leader] + offset. Its equation comes
    /// after those of the loops.
    ///
    /// \param[in] name How messages call it ("coupling #1" when empty).
    /// \throws std::invalid_argument for an unknown joint, a joint with other than one
    ///         configuration entry and one velocity, the same joint twice, or a non-finite
    ///         multiplier or offset.
    ///
    void addCoupling(
      pinocchio::JointIndex follower,
      pinocchio::JointIndex leader,
      double multiplier,
      double offset,
      const std::string & name = std::string());

    const std::vector<Loop> & loops() const
    {
      return loops_;
    }
    const std::vector<JointCoupling> & couplings() const
    {
      return couplings_;
    }
    /// \brief No loop and no coupling.
    bool empty() const
    {
      return loops_.empty() && couplings_.empty();
    }
    /// \brief Number of constraint equations (3 per point loop, 6 per frame loop, 1 per
    /// coupling).
    int rows() const
    {
      return rows_;
    }
    const pinocchio::Model & model() const
    {
      return model_;
    }

  private:
    const pinocchio::Model & model_;
    std::vector<Loop> loops_;
    std::vector<JointCoupling> couplings_;
    int rows_ = 0;
  };

  ///
  /// \brief Constraint error at q: stacked loop errors (dim loops.rows(), m or rad).
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  ///
  Eigen::VectorXd computeLoopError(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q);

  ///
  /// \brief Constraint Jacobian at q (dim loops.rows() x model.nv): the constraint error's rate
  /// of change per unit joint velocity (exact on the constraint manifold).
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  ///
  Eigen::MatrixXd computeLoopJacobian(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q);

  /// \brief How the loops leave a mechanism free to move at a configuration.
  struct LoopMotion
  {
    /// Independent constraint equations (rank of the Jacobian).
    int rank = 0;
    /// Orthonormal basis of the joint velocities the loops allow (dim model.nv x mobility).
    Eigen::MatrixXd basis;
    /// Largest constraint error (m or rad).
    double error = 0.;
  };

  ///
  /// \brief The motions the loops allow at q: the null space of the constraint Jacobian (by SVD,
  /// rank cut at 1e-9 times the largest singular value, so redundant equations are dropped).
  ///
  LoopMotion computeLoopMotion(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q);

  ///
  /// \brief Move q onto the constraint manifold: Gauss-Newton steps q <- q (+) -J^+ e(q) (least
  /// norm in joint coordinates), each kept only if it lowers the error.
  ///
  /// \param[in,out] q The joint configuration (dim model.nq).
  /// \param[in] tolerance Stop once max |e| <= tolerance (m or rad).
  /// \param[in] max_iterations Most Gauss-Newton steps.
  /// \param[in] pinned Indices in v of 1-DoF joints that must not move (joints on a stop), or
  ///            nullptr.
  /// \return The largest constraint error left (m or rad).
  ///
  double projectOntoLoops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    Eigen::VectorXd & q,
    double tolerance = 1e-13,
    int max_iterations = 50,
    const std::vector<Eigen::Index> * pinned = nullptr);

  ///
  /// \brief Assemble the loops from a start configuration, or say why it cannot be done.
  ///
  /// \param[in,out] q The start configuration (dim model.nq), moved onto the loops.
  /// \return How far q moved (max |difference|, rad or m).
  /// \throws std::invalid_argument when the error stays above 1e-10 (m or rad): the message names
  ///         the loop left open and by how much.
  ///
  double assembleLoops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    Eigen::VectorXd & q);

  ///
  /// \brief Net static generalized force of the closed mechanism at q: the static force
  /// (computeStaticForce) minus the constraint reactions that best balance it, i.e. its
  /// component along the motions the loops allow, P tau with P the orthogonal projector onto
  /// the null space of the constraint Jacobian. Zero at an equilibrium.
  ///
  /// \param[in] q The joint configuration (dim model.nq), on the loops.
  /// \return P tau (dim model.nv, N m or N).
  ///
  Eigen::VectorXd computeStaticForce(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Stiffness of the closed mechanism at q, restricted to the motions the loops allow:
  /// K_r = N^T (K - d(J^T lambda)/dq) N, with N the orthonormal basis of computeLoopMotion, K
  /// the tree's stiffness (computeStiffnessMatrix) and lambda the least-squares constraint
  /// reactions J^T lambda = tau_static; the second term (the constraint's curvature under its
  /// reactions) by central differences along N.
  ///
  /// \return The report with stiffness = K_r (dim mobility x mobility), its eigenvalues, and
  ///         softest_direction = N u (dim model.nv), a joint velocity the loops allow.
  ///
  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Loops and stops together: the stops' share of the net static force of the closed
  /// mechanism at q.
  ///
  struct StopBalance
  {
    /// What neither the loops nor the stops balance (dim model.nv, N m or N): P (tau - E^T mu)
    /// with P the projector of computeStaticForce and mu the reactions below.
    Eigen::VectorXd unbalanced;
    /// Every joint on a stop at q, with its reaction (>= 0; 0 when the stop would have to pull).
    std::vector<StopContact> contacts;
    /// |unbalanced|_inf: the residual of a rest against stops on a closed mechanism.
    double residual = 0.;
  };

  ///
  /// \brief The stops' reactions that best balance the net static force of the closed mechanism
  /// (least squares over the motions the loops allow), each pushing only away from its stop: a
  /// stop that would have to pull is let go and the rest solved again.
  ///
  /// \param[in] q The joint configuration (dim model.nq), on the loops and inside the stops.
  /// \param[in] tau The net static force P tau of computeStaticForce with loops (dim model.nv).
  ///
  StopBalance balanceStops(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau);

  ///
  /// \brief Stability of a rest of a closed mechanism against stops: the stiffness of
  /// assessStability with loops restricted further to the motions that keep the joints whose
  /// stop pushes (reaction above 1e-9 of the largest static force) on it.
  ///
  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const JointStops & stops,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Time scales of the closed mechanism linearised at q: those of computeTimeScale for
  /// the reduced stiffness, inertia N^T M N, pull N^T tau and damping N^T D N. No stiff-mode
  /// scaling (TimeScale::stiff_masses stays empty).
  ///
  TimeScale computeTimeScale(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const LoopConstraints & loops,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

} // namespace pinsettle

#endif // ifndef __pinsettle_loops_hpp__
