//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/damping.hpp"

#include <numeric>

namespace pinsettle
{

  StoppingWindow::StoppingWindow(std::int64_t ds, double max_e)
  : samples_(static_cast<std::size_t>(ds), 0.)
  , max_e_(max_e)
  {
  }

  void StoppingWindow::record(double e)
  {
    samples_[next_] = e;
    next_ = (next_ + 1) % samples_.size();
    if (count_ < samples_.size())
      ++count_;
    still_ = e == 0. ? still_ + 1 : 0;
  }

  bool StoppingWindow::isQuiet(double e) const
  {
    return count_ == samples_.size() && e <= max_e_
           && std::accumulate(samples_.begin(), samples_.end(), 0.) <= max_e_;
  }

} // namespace pinsettle
