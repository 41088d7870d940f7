//
// Settle a URDF robot from its neutral configuration and print where it comes to rest.
//
//   settle_urdf path/to/robot.urdf [kt]
//
// Build it against an installed pinsettle (see examples/CMakeLists.txt).
//

#include <pinsettle/pinsettle.hpp>

#include <pinocchio/algorithm/joint-configuration.hpp>

#include <cstdlib>
#include <iostream>

int main(int argc, char ** argv)
{
  if (argc < 2)
  {
    std::cerr << "usage: " << argv[0] << " ROBOT.urdf [kt]\n";
    return 2;
  }
  try
  {
    const pinocchio::Model model = pinsettle::buildModelFromUrdf(argv[1]);

    pinsettle::Settings settings;
    settings.max_e = 1e-16; // J summed over the last ds = 10 steps
    if (argc > 2)
      settings.kt = std::atof(argv[2]);

    pinsettle::Solver solver(model);
    const Eigen::VectorXd q0 = pinocchio::neutral(model);
    const pinsettle::Result result = solver.solve(q0, settings);

    std::cout << "status    " << pinsettle::toString(result.status) << "\n"
              << "steps     " << result.info.steps << " (" << result.info.peaks
              << " damping events)\n"
              << "wall time " << result.info.wall_time * 1e3 << " ms\n"
              << "residual  " << result.residual << " N m\n";
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
      std::cout << "  " << model.names[j] << " "
                << result.q.segment(model.idx_qs[j], model.nqs[j]).transpose() << "\n";
    return result.status == pinsettle::Status::Converged ? 0 : 1;
  }
  catch (const std::exception & e)
  {
    std::cerr << "error: " << e.what() << "\n";
    return 2;
  }
}
