//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_contact_impulses_hpp__
#define __pinsettle_contact_impulses_hpp__

#include <Eigen/Core>

#include <vector>

namespace pinsettle
{

  ///
  /// \brief Memory of solveContactImpulses, grown by it when too small (a step loop's is sized
  /// by its first solves, then reused).
  ///
  struct ImpulseWorkspace
  {
    /// Y lambda (dim Y.rows()): out, the impulses' velocity change in Y's space.
    Eigen::VectorXd w;
    /// w at the start of a sweep.
    Eigen::VectorXd w_sweep;
    /// The step lengths of each contact's update and each unilateral row's.
    Eigen::Matrix2Xd steps;
    /// The rows' velocities u = Y^T Y lambda + b of the impulses last checked (dim Y.cols()).
    Eigen::VectorXd u;
    /// Y times the impulses last checked (dim Y.rows()).
    Eigen::VectorXd y_lambda;
    /// The active-set solve's candidate impulses (dim Y.cols()).
    Eigen::VectorXd trial;
    /// Its unknowns: each column the impulses one unknown stands for (Y.cols() x unknowns).
    Eigen::MatrixXd basis;
    /// Y times basis, and the equations' rows of Y^T Y basis.
    Eigen::MatrixXd y_basis, system;
    /// The equations' right-hand side and the unknowns' solution.
    Eigen::VectorXd rhs, x;
    /// The rows whose velocity the active set holds at zero.
    std::vector<Eigen::Index> equations;
    /// Each contact's and then each unilateral row's set in the active-set solve.
    std::vector<signed char> set;
    /// Each contact's friction direction (t1, t2) while it slides in the active-set solve.
    Eigen::Matrix2Xd slide;
  };

  /// The impulses are solved until no row's velocity breaks its law (Signorini's, Coulomb's) by
  /// more than this times the largest velocity without impulses (|b|_inf).
  constexpr double kImpulseTolerance = 1e-10;

  ///
  /// \brief Solve the contact impulses of a step: lambda in the friction cones (three per
  /// active pair, ordered t1, t2, n), then one >= 0 per frictionless unilateral row (a joint
  /// on its stop), with the velocities u = Y^T Y lambda + b complementary to them.
  ///
  /// Projected Gauss-Seidel in the space of Y lambda, started from lambda; where its sweeps
  /// stall, or every power of two of them from 64, the sets they show (which rows are closed,
  /// which contacts stick and which slide, and which way) are solved exactly (least norm over
  /// redundant rows) and taken when every row then keeps its law to kImpulseTolerance. A stall
  /// is no answer by itself: on gymnasium's walker2d lying on its floor, the sweeps stood still
  /// for a while with normal velocities 0.08 m/s off, which the next step's gap terms turned
  /// into motion that never stopped.
  ///
  /// \param[in] Y A factor of the Delassus matrix G = J M^-1 J^T = Y^T Y of the active rows,
  ///            e.g. L^-1 J^T with M = L L^T (nv x (3a + s)).
  /// \param[in] b Velocities without impulses, the gap terms included (dim 3a + s).
  /// \param[in] friction Coefficient of each active pair (dim a).
  /// \param[in,out] lambda Impulses (dim 3a + s, N s or N m s): the start in, the answer out.
  /// \param[in,out] work Its memory; work.w = Y lambda out.
  /// \param[in] round_off The rows' velocities' round-off (m/s or rad/s), below which no law
  ///            can be told apart: the tolerance is at least that (a ball rolling 56 m from the
  ///            origin at 320 rad/s has its contact point's velocity to 2e-12 m/s only).
  /// \return The number of sweeps.
  ///
  int solveContactImpulses(
    const Eigen::Ref<const Eigen::MatrixXd> & Y,
    const Eigen::Ref<const Eigen::VectorXd> & b,
    const Eigen::Ref<const Eigen::VectorXd> & friction,
    Eigen::Ref<Eigen::VectorXd> lambda,
    ImpulseWorkspace & work,
    double round_off = 0.);

  ///
  /// \brief How far impulses are from solving the step (solveContactImpulses): the largest
  /// velocity (m/s or rad/s) by which a row breaks its law. A normal or unilateral row that
  /// pushes must not move (|u|), one that does not must not close (max(0, -u)); a contact that
  /// sticks (its tangential impulse inside its cone) must not slide (|u_t|); one on its cone's
  /// edge may only slide against its friction (the part of u_t across it, and any along it).
  ///
  double computeImpulseResidual(
    const Eigen::Ref<const Eigen::MatrixXd> & Y,
    const Eigen::Ref<const Eigen::VectorXd> & b,
    const Eigen::Ref<const Eigen::VectorXd> & friction,
    const Eigen::Ref<const Eigen::VectorXd> & lambda,
    ImpulseWorkspace & work);

} // namespace pinsettle

#endif // ifndef __pinsettle_contact_impulses_hpp__
