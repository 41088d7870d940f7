//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_damping_hpp__
#define __pinsettle_damping_hpp__

#include <cstdint>
#include <vector>

namespace pinsettle
{

  ///
  /// \brief The three-sample peak rule on the energy signal.
  ///
  /// The middle of the last three samples of one undamped stretch is a peak when it exceeds both
  /// neighbours by more than err times itself (relative, so that peaks are still found after the
  /// energy has fallen by many decades). The peak is seen one step late. A flat top, the middle
  /// sample exactly equal to the one before it and above the next, is a peak too: the samples of
  /// a periodic orbit of the integrator repeat exactly (one mode at h omega = 1 turns 60 degrees a
  /// step), and the rule would never see its tops.
  ///
  class PeakDetector
  {
  public:
    /// \param[in] err Relative threshold (>= 0, dimensionless).
    explicit PeakDetector(double err = 0.)
    : err_(err)
    {
    }

    /// \brief Forget every sample (the start of a run, a damping event, a push, a roll-back):
    /// the samples of an interrupted stretch say nothing about the next one.
    void restart()
    {
      fresh_ = 0;
    }

    /// \brief Whether the newest sample e makes the previous one a peak (nothing is recorded).
    bool isPeak(double e) const
    {
      return fresh_ >= 2 && (e_prev_ - e_prev2_ > err_ * e_prev_ || e_prev_ == e_prev2_)
             && e_prev_ - e > err_ * e_prev_;
    }

    /// \brief Whether e is at most the previous sample of the stretch: falling, or flat (an
    /// orbit whose samples repeat exactly: the three-sample rule sees no peak in it).
    bool isNotRising(double e) const
    {
      return fresh_ >= 1 && e <= e_prev_;
    }

    /// \brief Whether the stretch has a sample before the current one.
    bool hasPrevious() const
    {
      return fresh_ >= 1;
    }

    /// \brief Add e to the stretch.
    void record(double e)
    {
      e_prev2_ = e_prev_;
      e_prev_ = e;
      ++fresh_;
    }

    ///
    /// \brief Where the peak lies, for backtracking: the parabola through the last two recorded
    /// samples and e at (-1, 0, 1) has its vertex x steps after the middle one; e lies 1 - x
    /// steps past the peak.
    ///
    /// \param[in] e The newest sample, for which isPeak(e) holds.
    /// \return 1 - x, in steps (between 0.5 and 1.5).
    ///
    double stepsPastPeak(double e) const
    {
      const double x = (e_prev2_ - e) / (2. * (e_prev2_ - 2. * e_prev_ + e));
      return 1. - x;
    }

  private:
    double err_;
    // The two samples before the current one, and the samples recorded since the last restart.
    double e_prev2_ = 0., e_prev_ = 0.;
    int fresh_ = 0;
  };

  ///
  /// \brief The stopping rule of kinetic damping: the energy summed over the last ds samples is
  /// at most max_e (the caller adds "and not rising"), and a whole window of exactly zero energy
  /// (a start at rest on an equilibrium, where the energy never decreases).
  ///
  /// Its memory is allocated by the constructor only.
  ///
  class StoppingWindow
  {
  public:
    /// \param[in] ds Window length (samples, >= 1).
    /// \param[in] max_e Bound on the window's sum (unit of the energy signal, >= 0).
    StoppingWindow(std::int64_t ds, double max_e);

    /// \brief Forget the samples (the stretch was interrupted).
    void restart()
    {
      count_ = 0;
      still_ = 0;
    }

    /// \brief Add the sample e (the oldest drops out of a full window).
    void record(double e);

    /// \brief Whether the window is full, its newest sample e is at most max_e and so is its
    /// sum (formed exactly, only when e <= max_e: a running sum would keep the round-off of the
    /// early, large energies).
    bool isQuiet(double e) const;

    /// \brief Whether the last ds samples were all exactly zero.
    bool isExactRest() const
    {
      return still_ >= static_cast<std::int64_t>(samples_.size());
    }

  private:
    std::vector<double> samples_;
    double max_e_;
    std::size_t next_ = 0, count_ = 0;
    // Samples in a row that were exactly zero.
    std::int64_t still_ = 0;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_damping_hpp__
