//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_contacts_hpp__
#define __pinsettle_contacts_hpp__

#include "pinsettle/contact-impulses.hpp"
#include "pinsettle/stability.hpp"
#include "pinsettle/stops.hpp"

#include <Eigen/Cholesky>

#include <string>
#include <vector>

namespace pinsettle
{

  ///
  /// \brief A contact at a rest: one point of a body against one ground plane, the force the
  /// ground exerts on the body there.
  ///
  struct GroundContact
  {
    /// The contact point's name (the scene's [[contact]] name, or its frame).
    std::string name;
    /// The ground's name.
    std::string ground;
    /// The contact point on the ground (world, m): the sphere's lowest point.
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
    /// The ground's unit normal (world), pointing out of the ground.
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    /// The force's component along the normal (N), >= 0.
    double normal_force = 0.;
    /// The force's component in the ground's plane (world, N).
    Eigen::Vector3d tangential_force = Eigen::Vector3d::Zero();
    /// Distance from the sphere to the plane (m): negative when it sinks in.
    double gap = 0.;
    /// Whether the tangential force is strictly inside the friction cone (|f_t| < mu f_n); a
    /// contact at the cone's edge would slide.
    bool sticking = true;
    /// Whether the rest hangs on this contact by a thread: it carries almost no force (at most
    /// kMarginalLoad of the load: the slightest push lifts it) or, when no forces balance the
    /// rest inside cones shrunk by kMarginalCone (ContactBalance::near_cone_edge), its
    /// tangential force is within kMarginalCone of its cone's edge (a push makes it slide).
    bool marginal = false;
  };

  /// A closed contact carrying at most this share of the load (describeContacts) is marginal.
  constexpr double kMarginalLoad = 1e-3;
  /// A rest that no forces balance within cones of (1 - kMarginalCone) mu is within 1 % of
  /// sliding: its contacts with |f_t| >= (1 - kMarginalCone) mu f_n are marginal.
  constexpr double kMarginalCone = 1e-2;

  ///
  /// \brief Grounds (planes and boxes) and the points (spheres of a radius, 0 for a point) of
  /// bodies that can touch them: hard unilateral contacts with Coulomb friction, inelastic.
  ///
  /// Every point is a candidate against every ground (a fixed set, sized once: the step loop
  /// allocates nothing). The gap of a sphere of centre c and radius r on a plane through o with
  /// unit normal n is n.(c - o) - r; the contact point is c - r n. On a box, n is the direction
  /// from the box's closest point to c (a face's normal, or an edge's or corner's direction),
  /// and inside the box the normal of its nearest face (touchGround).
  ///
  class GroundContacts
  {
  public:
    /// \brief A ground: a plane or a box, its friction coefficient.
    struct Ground
    {
      enum class Shape
      {
        Plane,
        Box
      };
      std::string name;
      Shape shape;
      /// A plane: a point on it; a box: its centre (world, m).
      Eigen::Vector3d point;
      /// A plane: unit tangents and normal (t1, t2, n) as columns, right-handed, n out of the
      /// ground; a box: its own axes (world).
      Eigen::Matrix3d axes;
      /// A box: half its size along each of its axes (m); a plane: zero.
      Eigen::Vector3d half_size;
      double friction; ///< Coulomb coefficient mu >= 0
    };
    /// \brief A contact point: the centre of a sphere fixed to a body.
    struct Point
    {
      std::string name;
      pinocchio::JointIndex joint;
      Eigen::Vector3d position; ///< in the joint's frame (m)
      double radius;            ///< >= 0 (m)
    };

    /// \param[in] model The mechanism (it must outlive the contacts).
    explicit GroundContacts(const pinocchio::Model & model);

    ///
    /// \brief Add a ground plane.
    /// \throws std::invalid_argument naming the ground for a normal of zero length, a
    ///         friction coefficient that is negative or not finite, or a non-finite point.
    ///
    void addPlane(
      const std::string & name,
      const Eigen::Vector3d & point,
      const Eigen::Vector3d & normal,
      double friction);

    ///
    /// \brief Add a ground box: its centre (world, m), its axes (a rotation: the box's frame
    /// to the world) and half its size along each axis (m).
    /// \throws std::invalid_argument naming the ground for axes that are not a rotation (to
    ///         1e-9), half sizes that are not finite and > 0, a friction coefficient that is
    ///         negative or not finite, or a non-finite centre.
    ///
    void addBox(
      const std::string & name,
      const Eigen::Vector3d & centre,
      const Eigen::Matrix3d & axes,
      const Eigen::Vector3d & half_size,
      double friction);

    ///
    /// \brief Add a contact point (a sphere of radius radius centred at position in the frame of
    /// joint).
    /// \throws std::invalid_argument naming the point for a joint out of range, a negative or
    ///         non-finite radius, or a non-finite position.
    ///
    void addPoint(
      const std::string & name,
      pinocchio::JointIndex joint,
      const Eigen::Vector3d & position,
      double radius);

    /// Whether there is nothing to touch (no ground or no point): the solver runs none of this.
    bool empty() const
    {
      return grounds_.empty() || points_.empty();
    }
    /// Number of candidate pairs (points x grounds), each of three constraint rows.
    int pairs() const
    {
      return static_cast<int>(grounds_.size() * points_.size());
    }
    const std::vector<Ground> & grounds() const
    {
      return grounds_;
    }
    const std::vector<Point> & points() const
    {
      return points_;
    }
    /// The ground of a pair: pairs run point by point, each against every ground in order.
    const Ground & groundOf(int pair) const
    {
      return grounds_[static_cast<std::size_t>(pair) % grounds_.size()];
    }
    /// The point of a pair (see groundOf).
    const Point & pointOf(int pair) const
    {
      return points_[static_cast<std::size_t>(pair) / grounds_.size()];
    }
    const pinocchio::Model & model() const
    {
      return model_;
    }

  private:
    const pinocchio::Model & model_;
    std::vector<Ground> grounds_;
    std::vector<Point> points_;
  };

  ///
  /// \brief Where a sphere touches a ground: the gap (m, negative when it sinks in), the contact
  /// point (world, m: the sphere's point closest to the ground) and the pair's axes (t1, t2, n)
  /// as columns (world, n out of the ground).
  ///
  /// \param[in] centre The sphere's centre (world, m).
  /// \param[in] radius Its radius (m, >= 0).
  ///
  void touchGround(
    const GroundContacts::Ground & ground,
    const Eigen::Vector3d & centre,
    double radius,
    double & gap,
    Eigen::Ref<Eigen::Vector3d> point,
    Eigen::Ref<Eigen::Matrix3d> axes);

  ///
  /// \brief The candidate pairs at a configuration: gaps, contact points and the Jacobian of
  /// each pair's three rows (t1, t2, n) of the body's velocity at its contact point.
  ///
  struct ContactGeometry
  {
    /// Gap of each pair (m), dim pairs().
    Eigen::VectorXd gap;
    /// Contact point of each pair (world, m), 3 x pairs().
    Eigen::Matrix3Xd point;
    /// Axes (t1, t2, n) of each pair as columns (world), 3 x 3 pairs(): a plane's own, a
    /// box's those of the face, edge or corner touched.
    Eigen::Matrix3Xd axes;
    /// Rows (t1, t2, n) of each pair, 3 pairs() x model.nv: J v is the contact point's velocity
    /// in the ground's axes (m/s).
    Eigen::MatrixXd jacobian;
  };

  ///
  /// \brief Gaps, contact points and Jacobians of every pair at q (runs
  /// pinocchio::computeJointJacobians on data).
  ///
  void computeContactGeometry(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    ContactGeometry & geometry);

  ///
  /// \brief Whether no contact sinks into a ground deeper than kContactGapTolerance at q: a
  /// pose that sinks one is no rest, whatever its forces (a Newton step of the springs alone
  /// may pass through the ground).
  ///
  bool isClearOfGrounds(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q);

  ///
  /// \brief The contacts' part of a step: the impulses of a step of length h from the free
  /// acceleration, folded into that acceleration so that the semi-implicit Euler step lands on
  /// a velocity the contacts allow (inelastic, sticking or sliding by Coulomb's law).
  ///
  /// Pairs that cannot close within the step (gap + h min(0, u_n) > 0) are left out; without
  /// any, the step costs one computeJointJacobians. The impulses start from the last step's.
  /// With joint stops, the joints that reach a stop within the step are one more unilateral
  /// row each in the same solve (a stop held apart from the contacts undid their impulses:
  /// go1 with its motors off sank into the floor).
  ///
  class ContactStepper
  {
  public:
    /// \param[in] stops Joint stops solved with the contacts, or nullptr.
    ContactStepper(const GroundContacts & contacts, const JointStops * stops);

    /// Forget the last step's impulses (the start of a run).
    void start();

    ///
    /// \param[in] model The model the acceleration was computed on (its mass matrix is used).
    /// \param[in] q, v The state at the step's start.
    /// \param[in,out] ddq The free acceleration in, the one with the contacts' impulses out.
    /// \param[in] h The step (s).
    ///
    void apply(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      Eigen::VectorXd & ddq,
      double h);

    ///
    /// \brief The stops the last step's impulses brought a joint onto from off them (further
    /// than kContactGapTolerance at the step's start, on them at q).
    /// \param[in] q The configuration after the step, its joints put on their stops
    ///            (enforceStops).
    /// \param[out] hits When given, their joints are appended to it (unless already there).
    /// \return Whether there were any.
    ///
    bool addStopsReached(
      const Eigen::VectorXd & q, std::vector<pinocchio::JointIndex> * hits) const;

  private:
    // The gaps, points and axes of every pair (geometry_, whose Jacobian is left empty: the
    // rows are written for the active pairs alone) and the pairs that close within the step
    // at vfree_ (active_).
    void findClosingPairs(const pinocchio::Model & model, const pinocchio::Data & data, double h);

    // Add the pairs not yet active that close within the step at the velocity (dim model.nv):
    // whether there were any.
    bool addClosingPairs(
      const pinocchio::Model & model,
      const pinocchio::Data & data,
      const Eigen::VectorXd & velocity,
      double h);

    // Add the stops not yet held that the velocity (dim model.nv) reaches within the step:
    // whether there were any.
    bool addClosingStops(const Eigen::VectorXd & q, const Eigen::VectorXd & velocity, double h);

    // Whether pair p closes within the step at the body velocities last computed.
    bool closesWithin(int p, double h) const;

    // Each body's spatial velocity at v (world axes, at the origin) into body_velocity_.
    void computeBodyVelocities(
      const pinocchio::Model & model, const pinocchio::Data & data, const Eigen::VectorXd & v);

    // The rows of the active pairs (t1, t2, n) and then of the held stops: Y_, b_ and the
    // impulses to start from (the last ones); their number.
    Eigen::Index assembleRows(
      const pinocchio::Model & model, const pinocchio::Data & data, double h);

    // The solved impulses kept as the pairs' forces and the stops' impulses.
    void keepImpulses(double h);

    Eigen::Index activeCount() const;

    const GroundContacts & contacts_;
    const JointStops * stops_;
    ContactGeometry geometry_;
    Eigen::Matrix<double, 6, Eigen::Dynamic> body_velocity_; // (m/s, rad/s) per joint
    std::vector<int> active_;
    std::vector<char> is_active_; // per pair
    Eigen::VectorXd force_;       // of each pair at the last step (N), 3 pairs()
    Eigen::MatrixXd Ja_, Y_;
    ImpulseWorkspace impulses_;
    Eigen::VectorXd b_, lambda_, mu_, vfree_, vnext_, dv_;
    double round_off_ = 0.;           // of the rows' velocities J vfree_ (m/s or rad/s)
    Eigen::VectorXd stop_sign_;       // of each stop: +1 held at its lower end, -1 at its upper, 0
    Eigen::VectorXd stop_gap_;        // of each held stop (rad or m)
    Eigen::VectorXd stop_impulse_;    // of each held stop (N m s or N s)
    Eigen::LLT<Eigen::MatrixXd> llt_; // of the mass matrix
  };

  /// \brief The contact forces (and the stops' reactions) that balance a static force at a
  /// rest, and what is left.
  struct ContactBalance
  {
    /// The joints on a stop with their reactions (>= 0), with stops.
    std::vector<StopContact> stops;
    /// One per pair (pairs()), 3 rows (t1, t2, n) each (N): J^T f balances tau (the static
    /// force, gravity minus the applied efforts).
    Eigen::VectorXd force;
    /// Pairs taken as closed (gap within the tolerance).
    std::vector<int> closed;
    /// What the forces leave unbalanced, tau - J^T f (dim model.nv, N m or N).
    Eigen::VectorXd left;
    /// |left|_inf (N m or N).
    double residual = 0.;
    /// The pairs at the rest's q the forces act through (its gaps, points and Jacobian).
    ContactGeometry geometry;
    /// Whether no forces balance inside the cones shrunk by kMarginalCone: the rest is within
    /// that much of sliding (the forces are then those in the cones themselves).
    bool near_cone_edge = false;
  };

  /// Gaps at most this (m) count as closed at a rest.
  constexpr double kContactGapTolerance = 1e-6;

  ///
  /// \brief The contact forces at a rest at q with static force tau (the generalized force of
  /// gravity and the applied efforts, dim model.nv): among the forces of the closed pairs that
  /// balance tau, in their friction cones and pressing, the one of least norm (for a support of
  /// more points than a rigid body needs, the rigid model leaves the share open: least norm
  /// shares it evenly where symmetry does). Where least norm leaves a cone shrunk by
  /// kMarginalCone, the forces nearest it inside those cones (alternating projections); where
  /// there are none, the rest is near_cone_edge and the forces those in the cones closest to
  /// balancing tau. With stops, the reactions of the joints on a stop (pushing, >= 0) are solved
  /// for with them.
  ///
  ContactBalance balanceContacts(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & tau,
    const JointStops * stops = nullptr);

  ///
  /// \brief Stability of a rest on the ground: the contacts that carry a force held as
  /// bilateral (at rest friction holds anywhere in the closed cone), the stiffness (with the
  /// contact forces' own, from the gap function, so that a ball on a floor is neutral) restricted
  /// to the motions they leave free, and those of the joints pressed on a stop. With every motion
  /// held, stable.
  ///
  StabilityReport assessStability(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const GroundContacts & contacts,
    const Eigen::VectorXd & q,
    const ForceModel * forces,
    const JointStops * stops = nullptr);

  ///
  /// \brief The contacts at a rest, for the result: each closed pair of balance (balanceContacts)
  /// with its forces and gap, and whether it is marginal.
  ///
  /// \param[in] load The scale of the loads the contacts share (N), e.g. the model's weight:
  ///            a contact carrying at most kMarginalLoad times the larger of it and the largest
  ///            normal force is marginal.
  ///
  std::vector<GroundContact> describeContacts(
    const GroundContacts & contacts, const ContactBalance & balance, double load = 0.);

} // namespace pinsettle

#endif // ifndef __pinsettle_contacts_hpp__
