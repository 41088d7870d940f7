//
// The baselines of the benchmark report (benchmarks/report.py), on the same Pinocchio dynamics
// as pinsettle's solver and timed the same way (std::chrono::steady_clock around the run):
//
//   viscous  plain viscous damping, what users of physics simulators do to let a robot settle:
//            the same damper c on every joint, integrated implicitly as simulators do (MuJoCo's
//            implicitfast): (M + dt c I) a = tau_elements(q, v) - c v - b(q, v), one ABA on the
//            model with dt c added to each joint's armature; then semi-implicit Euler with a
//            fixed step.
//   mass_damping  viscous damping proportional to the mass matrix (dynamic relaxation's
//            classic form): a = ABA(q, v, tau_elements(q, v)) - c v, which damps every mode at the
//            same rate c / 2 (where the joint dampers damp light links far faster than heavy ones).
//   adr      adaptive dynamic relaxation (Underwood, 1983), on the true dynamics: the
//            mass-proportional damping above with its c re-estimated every step from the
//            Rayleigh quotient of the last step's motion, omega^2 = dq . dtau_static / dq^T M dq
//            (c = damping_factor 2 omega, 0 where the quotient is not positive, at most
//            2 omega_max), and the step re-estimated with it (dt_safety times the damped limit
//            below). Every step also evaluates tau_static (one RNEA) and dq^T M dq (a kinetic
//            energy pass).
//   fire     FIRE (Bitzek et al., 2006) with its classic parameters: the power P = F . v of the
//            static force F = -tau_static(q) is watched; P <= 0 zeroes the velocity, halves the
//            step and resets the mixing; P > 0 mixes the velocity toward F and after N_min such
//            steps grows the step (x f_inc, at most dt_max) and shrinks alpha (x f_alpha). The
//            motion is the same semi-implicit Euler on ABA; every step also evaluates F (one
//            RNEA).
//   fire2    FIRE 2.0 (Guenole et al., 2020), written from the paper's description: semi-implicit
//            Euler with the mixing applied after the velocity update, N_delay 20 steps before the
//            step may grow, and none of the first N_delay steps shrinks it (initial delay),
//            alpha_start 0.25, dt_min = 0.02 dt0, at P <= 0 half a step back (q -= dt v / 2)
//            before the velocity is zeroed, and a stop after 2,000 uphill steps in a row.
//
//   newton   Newton's method from the start, globalised by a trust region on the potential
//            energy V (gravity's, less the work of the springs and loads from the start: its
//            gradient is tau_static, its Hessian the stiffness K of
//            pinsettle::computeStiffnessMatrix). Each iteration minimises the quadratic model
//            g.p + p^T K p / 2 within |p|_2 <= radius (rad and m alike) exactly, from the
//            eigenvectors of K's symmetric part (More and Sorensen, 1983): the Newton step where
//            K is positive definite and the step fits, else the boundary step of the shifted
//            system K + sigma I, the hard case included, so that negative curvature leads
//            downhill instead of to the nearest saddle. The step is taken where V fell by at
//            least 1e-4 of the predicted fall (where the fall is below V's round-off: where
//            the residual fell); the radius is quartered below a ratio of 1/4 and doubled
//            (at most kMaxRadius) above 3/4 on the boundary. Set-up: none.
//
// With `newton 1` a damped baseline finishes as the solver's default does: at a residual check
// at least max(check_every, nv^2 / 4) steps after its last try (the solver's spacing of its
// takeover tries), Newton's guarded takeover (pinsettle::Solver::settleByNewton) is tried from
// where the run stands and ends it when it gets to round-off; a run that reaches its target
// first is polished (pinsettle::Solver::polishRest). The solver is made before the timed
// set-up, as kd_profile's is before its timed solve.
//
// FIRE's velocity mixing, v <- (1 - alpha) v + alpha |v| F / |F|, is taken in joint coordinates
// (metric euclid: N m mixed with N, rad/s with m/s) or in the mass-matrix metric (metric mass:
// v <- (1 - alpha) v + alpha |v|_M d / |d|_M with d = M^-1 F, one more ABA at zero velocity, and
// |v|_M^2 = v^T M v, one kinetic-energy pass).
//
// Each baseline gets what the solver gets: the start (never the answer). Its set-up, timed and
// reported apart (setup_seconds), linearises the mechanism at the start as the solver's first
// step estimate does: M (crba), K (pinsettle::computeStiffnessMatrix) and the static force, then
// the explicit stability limit 2 / omega_max (pinsettle::computeTimeScale, no stiff-mode
// scaling: the baselines have none). The viscous rule c damps the softest mode of that
// linearisation critically (K phi = lambda M phi, phi M-normalised, the smallest |lambda| above
// 1e-6 omega_max^2, omega = sqrt|lambda|; none: omega = omega_max, as on a chain held
// horizontal, whose motion only the pull of gravity sets): c = 2 omega (mass-proportional) or
// 2 omega / |phi|^2 (joint dampers), times damping_factor. The mass-proportional step is
// dt_safety times the stability limit with that damping, 4 / (c + sqrt(c^2 + 4 omega_max^2));
// the joint dampers', integrated implicitly, dt_safety times the undamped limit 2 / omega_max
// (their damping does not bound the step). FIRE's dt_max is dt_max times the limit,
// dt0 = dt_max / 10.
//
// A run that blows up (non-finite values, or a residual 1e6 times the start's) or stalls (FIRE:
// 1,000 velocity resets without the residual falling tenfold; FIRE 2.0 also after 2,000 uphill
// steps in a row) is tried again with every step halved, up to 6 times.
//
//   baselines SPEC          (SPEC: benchmarks/spec.hpp)
//
// Prints one JSON object: status (converged, max_steps, time_limit, diverged or stalled),
// steps, the loop's wall time and the set-up's of each timed run, the final residual, q, the
// steps and coefficients used, the halvings and why, and FIRE's velocity resets.
//

#include "spec.hpp"

#include <pinsettle/prebuilt.hpp>
#include <pinocchio/algorithm/energy.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <memory>
#include <optional>

namespace
{
  typedef std::chrono::steady_clock Clock;
  using bench::Spec;
  using bench::Workspace;

  double since(Clock::time_point start)
  {
    return std::chrono::duration<double>(Clock::now() - start).count();
  }

  struct Outcome
  {
    std::string status = "max_steps";
    long steps = 0;
    double residual = 0., seconds = 0., setup_seconds = 0.;
    double dt = 0., dt_max = 0., dt_end = 0., damping = 0., omega_rule = 0., limit = 0.;
    long resets = 0;            // FIRE's velocity resets; Newton's rejected steps
    long newton_tries = 0;      // `newton 1`: takeovers tried
    long newton_iterations = 0; // ... and the Newton iterations of the one kept or the polish
    bool by_newton = false;     // ... whether the takeover ended the run
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
  constexpr double kFireFInc = 1.1, kFireFDec = 0.5, kFireAlphaStart = 0.1, kFireFAlpha = 0.99;
  // FIRE 2.0's (Guenole et al., 2020).
  constexpr int kFire2NDelay = 20, kFire2MaxUphill = 2000;
  constexpr double kFire2AlphaStart = 0.25, kFire2DtMinFactor = 0.02;
  // dt0 = dt_max / kDtMaxOverDt0 (the classic ratio).
  constexpr double kDtMaxOverDt0 = 10.;
  // A residual this many times the start's, or a non-finite value, is a divergence.
  constexpr double kBlowUp = 1e6;
  // FIRE stalls after this many resets without the residual falling tenfold.
  constexpr long kStallResets = 1000;
  // Step halvings tried on a divergence or a stall.
  constexpr int kMaxHalvings = 6;
  // The viscous rule damps the softest mode with lambda above this fraction of omega_max^2.
  constexpr double kSoftestMode = 1e-6;

  // factor times semi-implicit Euler's stability limit under mass-proportional damping c (1/s)
  // with the fastest mode omega_max (rad/s): 4 / (c + sqrt(c^2 + 4 omega_max^2)) (s).
  double dampedStep(double factor, double c, double omega_max)
  {
    return factor * 4. / (c + std::sqrt(c * c + 4. * omega_max * omega_max));
  }

  // What a baseline takes from the start: its steps and damping (see the top of the file).
  void setUp(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    const Spec & spec,
    double scale,
    Workspace & w,
    Outcome & out)
  {
    pinsettle::prebuilt::crba(model, w.data, w.q);
    Eigen::MatrixXd M = w.data.M;
    M.triangularView<Eigen::StrictlyLower>() = M.transpose();
    const Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model, w.data, w.q, elements);
    const Eigen::MatrixXd Ks = 0.5 * (K + K.transpose());
    bench::staticForce(model, elements, w);
    const pinsettle::TimeScale ts = pinsettle::computeTimeScale(Ks, M, w.force, nullptr, false);
    const double omega = ts.omega_max;
    out.limit = ts.critical_step;
    if (spec.method == "fire" || spec.method == "fire2")
    {
      out.dt_max = scale * spec.dt_max * out.limit;
      out.dt = out.dt_max / kDtMaxOverDt0;
      return;
    }
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> modes(Ks, M);
    const Eigen::VectorXd & lambda = modes.eigenvalues();
    // Modes far softer than the time scale (a chain held horizontal has no stiffness at all:
    // its motion is set by the pull of gravity) are not the ones to damp.
    const double tol = kSoftestMode * omega * omega;
    Eigen::Index softest = -1;
    for (Eigen::Index k = 0; k < lambda.size(); ++k)
      if (
        std::abs(lambda[k]) > tol
        && (softest < 0 || std::abs(lambda[k]) < std::abs(lambda[softest])))
        softest = k;
    out.omega_rule = softest >= 0 ? std::sqrt(std::abs(lambda[softest])) : omega;
    if (spec.method == "mass_damping" || spec.method == "adr")
    {
      out.damping = spec.damping_factor * 2. * out.omega_rule;
      out.dt = dampedStep(scale * spec.dt_safety, out.damping, omega);
    }
    else
    {
      // |phi|^2 of an M-normalised mode is about 1 / its mass; without a mode, the mean one.
      const double phi2 = softest >= 0 ? modes.eigenvectors().col(softest).squaredNorm()
                                       : static_cast<double>(model.nv) / M.trace();
      out.damping = spec.damping_factor * 2. * out.omega_rule / phi2;
      out.dt = scale * spec.dt_safety * out.limit;
    }
    out.dt_max = out.dt;
  }

  // FIRE's mixing: v <- (1 - alpha) v + alpha |v| F / |F| (w.force holds tau_static = -F), in
  // joint coordinates or in the mass-matrix metric. Needs w.tau, w.fext at (q, 0), as
  // bench::staticForce leaves them.
  void mix(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    bool mass_metric,
    double alpha,
    Workspace & w)
  {
    if (!mass_metric)
    {
      const double force_norm = w.force.norm();
      if (force_norm > 0.)
        w.v = (1. - alpha) * w.v - (alpha * w.v.norm() / force_norm) * w.force;
      return;
    }
    // d = M^-1 F = ABA(q, 0, applied): M^-1 (applied - gravity).
    bench::forwardDynamics(model, elements, w.q, w.zero, w);
    const double d_norm = std::sqrt(std::max(-w.data.ddq.dot(w.force), 0.)); // |d|_M = sqrt(d.F)
    const double v_norm =
      std::sqrt(2. * pinocchio::computeKineticEnergy(model, w.data, w.q, w.v)); // |v|_M
    if (d_norm > 0.)
      w.v = (1. - alpha) * w.v + (alpha * v_norm / d_norm) * w.data.ddq;
  }

  // One run of a baseline from the spec's start (see the top of the file): the state its steps
  // carry from one to the next, and the parts of a step.
  class BaselineRun
  {
  public:
    // The workspace at the start and the set-up (timed apart from the run).
    BaselineRun(
      const pinocchio::Model & model,
      const pinsettle::ForceElements * elements,
      const Spec & spec,
      double scale)
    : model_(model)
    , damped_(model)
    , elements_(elements)
    , spec_(spec)
    , w_(model)
    , fire_(spec.method == "fire")
    , fire2_(spec.method == "fire2")
    , viscous_(spec.method == "viscous")
    , mass_damping_(spec.method == "mass_damping" || spec.method == "adr")
    , adr_(spec.method == "adr")
    , mass_metric_(spec.metric == "mass")
    , scale_(scale)
    {
      w_.q = spec.q0;
      w_.v.setZero();
      const Clock::time_point setup_start = Clock::now();
      setUp(model, elements, spec, scale, w_, out_);
      dt_ = out_.dt;
      alpha_ = fire2_ ? kFire2AlphaStart : kFireAlphaStart;
      dt_min_ = kFire2DtMinFactor * out_.dt;
      start_residual_ = residual();
      progress_ = start_residual_;
      if (viscous_) // the dampers taken implicitly: M + dt c I in ABA
        damped_.armature.array() += dt_ * out_.damping;
      out_.setup_seconds = since(setup_start);
      // Made once, outside the timed set-up, as the solver that kd_profile times is.
      if (spec.newton)
        solver_ = std::make_unique<pinsettle::Solver>(model);
      newton_spacing_ = std::max<long>(
        spec.check_every, static_cast<long>(model.nv) * static_cast<long>(model.nv) / 4);
    }

    Outcome run(Recorder & recorder)
    {
      start_ = Clock::now();
      long step = 0;
      for (; step < spec_.max_steps; ++step)
      {
        recorder.record(step, w_.q);
        if (checksResidual(step) && (residualEnds(step) || isSettledByNewton(step)))
        {
          // Newton's finish (takeover or polish) counts as one more step: its rest is the
          // curve's last sample.
          step += out_.by_newton || out_.newton_iterations > 0;
          break;
        }
        if ((fire_ || fire2_) && powerEnds(step))
          break;
        if (!advance())
        {
          out_.status = "diverged";
          ++step;
          break;
        }
      }
      out_.seconds = since(start_);
      out_.steps = step;
      out_.dt_end = dt_;
      out_.q = w_.q;
      out_.residual = residual();
      return out_;
    }

  private:
    // max |tau_static(q)|, leaving tau_static in w_.force.
    double residual()
    {
      return bench::staticResidual(model_, elements_, w_);
    }

    // FIRE and ADR need the static force at every step; viscous damping checks every
    // check_every.
    bool checksResidual(long step) const
    {
      return fire_ || fire2_ || adr_ || step % spec_.check_every == 0;
    }

    // ADR: c from the Rayleigh quotient of the last step's motion w_.dq, tau_static having
    // gone from force_prev_ to w_.force along it; the step re-estimated with c.
    void adaptDamping()
    {
      if (have_prev_)
      {
        const double stiffness = w_.dq.dot(w_.force - force_prev_); // dq^T K dq
        const double inertia = 2. * pinocchio::computeKineticEnergy(model_, w_.data, w_.q, w_.dq);
        const double omega_max = 2. / out_.limit;
        const double omega2 = inertia > 0. ? stiffness / inertia : 0.;
        out_.damping = omega2 > 0.
                         ? std::min(spec_.damping_factor * 2. * std::sqrt(omega2), 2. * omega_max)
                         : 0.;
        dt_ = dampedStep(scale_ * spec_.dt_safety, out_.damping, omega_max);
      }
      force_prev_ = w_.force;
      have_prev_ = true;
    }

    bool end(const char * status)
    {
      out_.status = status;
      return true;
    }

    // The residual check: true when it ends the run (diverged, converged or out of time).
    bool residualEnds(long step)
    {
      const double residual = this->residual();
      if (!(residual <= kBlowUp * start_residual_)) // also catches NaN
        return end("diverged");
      if (residual <= spec_.target)
      {
        polish();
        return end("converged");
      }
      if (residual <= 0.1 * progress_)
      {
        progress_ = residual;
        stall_resets_ = 0;
      }
      if (step % 1024 == 0 && since(start_) > spec_.max_time)
        return end("time_limit");
      return false;
    }

    // `newton 1`: the solver's takeover, tried every newton_spacing_ steps at a residual check;
    // true when it ended the run at a rest.
    bool isSettledByNewton(long step)
    {
      if (!solver_ || step - newton_tried_at_ < newton_spacing_)
        return false;
      newton_tried_at_ = step;
      ++out_.newton_tries;
      const std::optional<pinsettle::Solver::NewtonRest> rest =
        solver_->settleByNewton(w_.q, settings_, elements_);
      if (!rest)
        return false;
      w_.q = rest->q;
      w_.v.setZero();
      out_.newton_iterations = rest->iterations;
      out_.by_newton = true;
      return end("converged");
    }

    // `newton 1`: the solver's polish of the rest the run converged to.
    void polish()
    {
      if (!solver_)
        return;
      const pinsettle::Solver::NewtonRest rest = solver_->polishRest(w_.q, elements_);
      w_.q = rest.q;
      out_.newton_iterations = rest.iterations;
    }

    // FIRE's power test: true when it ends the run (stalled).
    bool powerEnds(long step)
    {
      // w_.force is tau_static; the force driving the mechanism toward rest is its opposite.
      const double power = -w_.force.dot(w_.v);
      if (power > 0.)
      {
        goingDownhill();
        return false;
      }
      return goingUphill(step);
    }

    void goingDownhill()
    {
      uphill_ = 0;
      ++positive_;
      if (positive_ > (fire2_ ? kFire2NDelay : kFireNMin))
      {
        dt_ = std::min(dt_ * kFireFInc, out_.dt_max);
        alpha_ *= kFireFAlpha;
      }
      if (fire_) // classic FIRE mixes before the step; FIRE 2.0 after the velocity update
        mix(model_, elements_, mass_metric_, alpha_, w_);
    }

    // The velocity reset; true when the run has stalled instead.
    bool goingUphill(long step)
    {
      ++out_.resets;
      positive_ = 0;
      if (stalls())
        return end("stalled");
      if (fire_)
      {
        dt_ *= kFireFDec;
        alpha_ = kFireAlphaStart;
      }
      else
        fire2StepBack(step);
      w_.v.setZero();
      return false;
    }

    // One more reset without progress; FIRE 2.0 also counts the uphill steps in a row.
    bool stalls()
    {
      if (++stall_resets_ >= kStallResets)
        return true;
      return fire2_ && ++uphill_ > kFire2MaxUphill;
    }

    void fire2StepBack(long step)
    {
      if (step >= kFire2NDelay) // the initial delay: no shrinking in the first steps
      {
        if (dt_ * kFireFDec >= dt_min_)
          dt_ *= kFireFDec;
        alpha_ = kFire2AlphaStart;
      }
      bench::moveBy(model_, -0.5 * dt_, w_); // half a step back
    }

    // One semi-implicit Euler step with the method's damping; false when a value turned
    // non-finite.
    bool advance()
    {
      if (adr_)
        adaptDamping();
      bench::appliedForces(model_, elements_, w_.q, w_.v, w_);
      if (viscous_)
        w_.tau.noalias() -= out_.damping * w_.v;
      bench::forwardDynamics(viscous_ ? damped_ : model_, elements_, w_.q, w_.v, w_);
      if (mass_damping_)
        w_.data.ddq.noalias() -= out_.damping * w_.v;
      w_.v.noalias() += dt_ * w_.data.ddq;
      if (fire2_ && w_.v.squaredNorm() > 0.)
      {
        // The mixing's F is the step's (w_.force, from the check above); its metric needs the
        // applied efforts at zero velocity.
        if (mass_metric_)
          bench::appliedForces(model_, elements_, w_.q, w_.zero, w_);
        mix(model_, elements_, mass_metric_, alpha_, w_);
      }
      return bench::moveBy(model_, dt_, w_);
    }

    const pinocchio::Model & model_;
    pinocchio::Model damped_; // model_ with dt c added to the armature (viscous only)
    const pinsettle::ForceElements * elements_;
    const Spec & spec_;
    Workspace w_;
    Outcome out_;
    const bool fire_, fire2_, viscous_, mass_damping_, adr_, mass_metric_;
    const double scale_;
    double dt_ = 0., alpha_ = 0., dt_min_ = 0.;
    Eigen::VectorXd force_prev_; // ADR: tau_static at the last step's start
    bool have_prev_ = false;
    int positive_ = 0, uphill_ = 0;
    long stall_resets_ = 0;
    double start_residual_ = 0.;
    double progress_ = 0.; // FIRE's stall test: resets since a tenfold fall
    Clock::time_point start_;
    std::unique_ptr<pinsettle::Solver> solver_; // `newton 1`
    const pinsettle::Settings settings_;        // the solver's defaults
    long newton_spacing_ = 0, newton_tried_at_ = 0;
  };

  // The trust region's largest radius (rad or m) and the ratios of its rule.
  constexpr double kMaxRadius = 10., kAcceptRatio = 1e-4, kShrinkRatio = 0.25, kGrowRatio = 0.75;
  // A predicted fall of V below this many ulps of V's terms is round-off: the residual decides.
  constexpr double kPotentialRoundOff = 1e3 * std::numeric_limits<double>::epsilon();

  // The trust-region step: argmin g.p + p^T K p / 2 subject to |p|_2 <= radius, from the
  // eigen-decomposition of K (ascending eigenvalues lambda, eigenvectors U); the predicted
  // change of V in `predicted`.
  Eigen::VectorXd trustRegionStep(
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> & eig,
    const Eigen::VectorXd & g,
    double radius,
    double & predicted)
  {
    const Eigen::VectorXd & lambda = eig.eigenvalues();
    const Eigen::MatrixXd & U = eig.eigenvectors();
    const Eigen::VectorXd gt = U.transpose() * g;
    // |p(sigma)|, p(sigma) = -(K + sigma I)^-1 g, leaving out the directions of the smallest
    // eigenvalue when `hard` (the hard case, where g has no part along them).
    const double lowest = lambda[0];
    const double g_norm = gt.norm();
    auto isLowest = [&](Eigen::Index k) {
      return lambda[k] - lowest <= 1e-12 * std::abs(lowest) + 1e-300;
    };
    auto coefficients = [&](double sigma, bool hard) {
      Eigen::VectorXd c(gt.size());
      for (Eigen::Index k = 0; k < gt.size(); ++k)
        c[k] = hard && isLowest(k) ? 0. : -gt[k] / (lambda[k] + sigma);
      return c;
    };
    // The coefficients of the step in U's basis.
    auto step = [&]() -> Eigen::VectorXd {
      if (lowest > 0.)
      {
        Eigen::VectorXd newton = coefficients(0., false);
        if (newton.norm() <= radius)
          return newton;
      }
      const double floor = std::max(0., -lowest);
      // The hard case: g (almost) orthogonal to the lowest eigenvectors, and the step of the
      // shifted system with sigma = -lowest inside the region: move along them to its edge.
      double along = 0.;
      for (Eigen::Index k = 0; k < gt.size(); ++k)
        if (isLowest(k))
          along += gt[k] * gt[k];
      Eigen::VectorXd inner = coefficients(floor, true);
      if (std::sqrt(along) <= 1e-12 * g_norm && inner.norm() <= radius && lowest <= 0.)
      {
        inner[0] += std::sqrt(std::max(radius * radius - inner.squaredNorm(), 0.));
        return inner;
      }
      // |p(sigma)| falls from infinity at sigma = floor to g_norm / (lowest + sigma): bisect
      // on 1 / |p| (nearly linear in sigma) between floor and floor + g_norm / radius.
      double lo = floor, hi = floor + g_norm / radius + std::abs(lowest);
      for (int k = 0; k < 200 && hi - lo > 1e-15 * std::max(1., hi); ++k)
      {
        const double mid = 0.5 * (lo + hi);
        (coefficients(mid, false).norm() > radius ? lo : hi) = mid;
      }
      return coefficients(hi, false);
    };
    const Eigen::VectorXd c = step();
    predicted = gt.dot(c) + 0.5 * c.dot(lambda.cwiseProduct(c));
    return U * c;
  }

  // Newton's method from the start with a trust region on the potential energy (see the top
  // of the file); one step is one iteration.
  class TrustRegionNewton
  {
  public:
    TrustRegionNewton(
      const pinocchio::Model & model,
      const pinsettle::ForceElements * elements,
      const Spec & spec,
      double scale)
    : model_(model)
    , elements_(elements)
    , spec_(spec)
    , w_(model)
    , motion_(Eigen::VectorXd::Zero(model.nv))
    , trial_motion_(model.nv)
    {
      w_.q = spec.q0;
      radius_ = scale * spec.radius;
      out_.dt = radius_;
    }

    Outcome run(Recorder & recorder)
    {
      start_ = Clock::now();
      double residual = this->residual();
      const double start_residual = residual;
      double potential = this->potential(w_.q, motion_);
      long step = 0;
      for (; step < spec_.max_steps; ++step)
      {
        recorder.record(step, w_.q);
        if (!(residual <= kBlowUp * start_residual))
          return finish("diverged", step);
        if (residual <= spec_.target)
          return finish("converged", step);
        if (since(start_) > spec_.max_time)
          return finish("time_limit", step);
        if (radius_ < 1e-15 * std::max(1., w_.q.lpNorm<Eigen::Infinity>()))
          return finish("stalled", step);
        const Eigen::VectorXd g = w_.force;
        Eigen::MatrixXd K = pinsettle::computeStiffnessMatrix(model_, w_.data, w_.q, elements_);
        K = 0.5 * (K + K.transpose()).eval();
        const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(K);
        double predicted = 0.;
        const Eigen::VectorXd p = trustRegionStep(eig, g, radius_, predicted);
        pinocchio::integrate(model_, w_.q, p, w_.q_next);
        trial_motion_ = motion_ + p;
        const double trial_potential = this->potential(w_.q_next, trial_motion_);
        w_.q.swap(w_.q_next);
        const double trial_residual = this->residual();
        const double ratio =
          this->ratio(trial_potential - potential, predicted, trial_residual < residual);
        const double length = p.norm();
        if (ratio < kShrinkRatio)
          radius_ = kShrinkRatio * length;
        else if (ratio > kGrowRatio && length >= 0.99 * radius_)
          radius_ = std::min(2. * radius_, kMaxRadius);
        if (ratio > kAcceptRatio && w_.q.allFinite())
        {
          motion_.swap(trial_motion_);
          potential = trial_potential;
          residual = trial_residual;
        }
        else
        {
          w_.q.swap(w_.q_next); // rejected: back to where it stood, and to its force
          w_.force = g;
          ++out_.resets;
        }
      }
      return finish("max_steps", step);
    }

  private:
    // max |tau_static(q)| at w_.q, leaving tau_static (V's gradient) in w_.force.
    double residual()
    {
      return bench::staticResidual(model_, elements_, w_);
    }

    // V at q, reached from the start by the net motion (J); its terms' size in scale_.
    double potential(const Eigen::VectorXd & q, const Eigen::VectorXd & motion)
    {
      const double gravity = pinsettle::computeGravityPotentialEnergy(model_, w_.data, q);
      const double work =
        elements_ ? elements_->computeWork(model_, w_.data, spec_.q0, q, motion) : 0.;
      scale_ = std::abs(gravity) + std::abs(work);
      return gravity - work; // NaN where the work is unknown (a point torque): residual decides
    }

    // Actual over predicted fall; where that is round-off (or V unknown), 1 if the residual
    // fell and 0 if not.
    double ratio(double actual, double predicted, bool residual_fell) const
    {
      if (!(predicted < -kPotentialRoundOff * scale_) || std::isnan(actual))
        return residual_fell ? 1. : 0.;
      return actual / predicted;
    }

    Outcome finish(const char * status, long step)
    {
      out_.status = status;
      out_.seconds = since(start_);
      out_.steps = step;
      out_.dt_end = radius_;
      out_.q = w_.q;
      out_.residual = residual();
      return out_;
    }

    const pinocchio::Model & model_;
    const pinsettle::ForceElements * elements_;
    const Spec & spec_;
    Workspace w_;
    Outcome out_;
    Eigen::VectorXd motion_, trial_motion_; // net tangent motion from the start (computeWork)
    double radius_ = 0., scale_ = 0.;
    Clock::time_point start_;
  };

  Outcome run(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * elements,
    const Spec & spec,
    double scale,
    Recorder & recorder)
  {
    if (spec.method == "newton")
      return TrustRegionNewton(model, elements, spec, scale).run(recorder);
    return BaselineRun(model, elements, spec, scale).run(recorder);
  }

  void checkMethod(const Spec & spec)
  {
    const char * const methods[] = {"viscous", "mass_damping", "adr", "fire", "fire2", "newton"};
    if (std::find(std::begin(methods), std::end(methods), spec.method) == std::end(methods))
      throw std::runtime_error(
        "method must be viscous, mass_damping, adr, fire, fire2 or newton, got '" + spec.method
        + "'");
    if (spec.newton && spec.method == "newton")
      throw std::runtime_error("newton 1 finishes a damped method; the method newton is Newton");
  }

  bool blewUpOrStalled(const Outcome & out)
  {
    return out.status == "diverged" || out.status == "stalled";
  }

  // The timed runs: the last one's outcome, the step scale they took, the halvings and why, and
  // each run's loop and set-up times.
  struct TimedRuns
  {
    Outcome out;
    double scale = 1.;
    int halvings = 0;
    std::vector<std::string> reasons;
    std::vector<double> seconds, setup;
  };

  TimedRuns timeRuns(
    const pinocchio::Model & model, const pinsettle::ForceElements * forces, const Spec & spec)
  {
    TimedRuns t;
    // A run that blows up or stalls is tried again with every step halved.
    Recorder none;
    t.out = run(model, forces, spec, t.scale, none);
    for (; blewUpOrStalled(t.out) && t.halvings < kMaxHalvings; ++t.halvings)
    {
      t.reasons.push_back(t.out.status);
      t.scale *= 0.5;
      t.out = run(model, forces, spec, t.scale, none);
    }
    t.seconds = {t.out.seconds};
    t.setup = {t.out.setup_seconds};
    double spent = t.out.seconds;
    for (int r = 1; r < spec.repeats && spent < spec.repeat_budget; ++r)
    {
      t.out = run(model, forces, spec, t.scale, none);
      t.seconds.push_back(t.out.seconds);
      t.setup.push_back(t.out.setup_seconds);
      spent += t.out.seconds;
    }
    return t;
  }

  // The final state, unless it is the last sample already (a run that stops on the residual
  // check stops right after recording).
  void recordFinalState(Recorder & recorder, const Outcome & recorded)
  {
    const std::size_t row = static_cast<std::size_t>(recorded.q.size()) + 1;
    std::vector<double> & rows = recorder.rows;
    if (rows.size() >= row && rows[rows.size() - row] == static_cast<double>(recorded.steps))
      return;
    rows.push_back(static_cast<double>(recorded.steps));
    rows.insert(rows.end(), recorded.q.data(), recorded.q.data() + recorded.q.size());
  }

  // The same run as the timed ones again, recording its samples into spec.samples_path.
  void writeSamples(
    const pinocchio::Model & model,
    const pinsettle::ForceElements * forces,
    const Spec & spec,
    const TimedRuns & timed)
  {
    Recorder recorder;
    recorder.every = std::max<long>(1, (timed.out.steps + spec.max_samples - 1) / spec.max_samples);
    // The same steps without the clock: recording makes the run slower, and a timed run that
    // ended just inside max_time would otherwise be replayed into its time limit.
    Spec replay = spec;
    replay.max_time = std::numeric_limits<double>::infinity();
    replay.max_steps = timed.out.steps;
    const Outcome recorded = run(model, forces, replay, timed.scale, recorder);
    recordFinalState(recorder, recorded);
    std::ofstream file(spec.samples_path, std::ios::binary);
    file.write(
      reinterpret_cast<const char *>(recorder.rows.data()),
      static_cast<std::streamsize>(recorder.rows.size() * sizeof(double)));
    const bool same_end = !timed.out.q.allFinite() || recorded.q == timed.out.q;
    if (recorded.steps != timed.out.steps || !same_end)
      throw std::runtime_error("the recorded run took another path than the timed runs");
  }

  void printJson(const Spec & spec, const TimedRuns & timed)
  {
    const Outcome & out = timed.out;
    std::cout << "{\"method\": \"" << spec.method << "\", \"metric\": \"" << spec.metric
              << "\", \"status\": \"" << out.status << "\", \"steps\": " << out.steps
              << ", \"wall_times\": " << bench::jsonVector(timed.seconds)
              << ", \"setup_times\": " << bench::jsonVector(timed.setup)
              << ", \"residual\": " << bench::number(out.residual)
              << ", \"dt\": " << bench::number(out.dt)
              << ", \"dt_max\": " << bench::number(out.dt_max)
              << ", \"dt_end\": " << bench::number(out.dt_end)
              << ", \"limit\": " << bench::number(out.limit)
              << ", \"damping\": " << bench::number(out.damping)
              << ", \"omega_rule\": " << bench::number(out.omega_rule)
              << ", \"newton_tries\": " << out.newton_tries
              << ", \"newton_iterations\": " << out.newton_iterations
              << ", \"by_newton\": " << (out.by_newton ? "true" : "false")
              << ", \"halvings\": " << timed.halvings << ", \"retries\": [";
    for (std::size_t k = 0; k < timed.reasons.size(); ++k)
      std::cout << (k ? ", " : "") << "\"" << timed.reasons[k] << "\"";
    std::cout << "], \"resets\": " << out.resets << ", \"q\": " << bench::jsonVector(out.q)
              << "}\n";
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
    const Spec spec = bench::readSpec(argv[1]);
    const pinocchio::Model model = bench::loadModel(spec);
    checkMethod(spec);
    pinsettle::ForceElements elements(model);
    bench::addElements(elements, spec);
    const pinsettle::ForceElements * forces = elements.empty() ? nullptr : &elements;
    const TimedRuns timed = timeRuns(model, forces, spec);
    if (!spec.samples_path.empty())
      writeSamples(model, forces, spec, timed);
    printJson(spec, timed);
  }
  catch (const std::exception & e)
  {
    std::cerr << argv[0] << ": " << e.what() << "\n";
    return 1;
  }
  return 0;
}
