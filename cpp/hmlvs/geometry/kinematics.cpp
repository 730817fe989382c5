#include "hmlvs/geometry/kinematics.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace hmlvs::geometry {

Eigen::Matrix4d DHLinkTransform(const DHJoint& joint, double reading, DHConvention convention) {
  const double theta = joint.prismatic ? joint.theta : reading + joint.offset;
  const double d = joint.prismatic ? reading + joint.offset : joint.d;
  const double ct = std::cos(theta), st = std::sin(theta);
  const double ca = std::cos(joint.alpha), sa = std::sin(joint.alpha);
  Eigen::Matrix4d t;
  if (convention == DHConvention::kStandard) {
    t << ct, -st * ca, st * sa, joint.a * ct,  //
        st, ct * ca, -ct * sa, joint.a * st,   //
        0, sa, ca, d,                          //
        0, 0, 0, 1;
  } else {
    t << ct, -st, 0, joint.a,            //
        st * ca, ct * ca, -sa, -sa * d,  //
        st * sa, ct * sa, ca, ca * d,    //
        0, 0, 0, 1;
  }
  return t;
}

Eigen::Matrix4d BaseFromHand(const DHRobot& robot,
                             const Eigen::Ref<const Eigen::VectorXd>& joints) {
  Eigen::Matrix4d t = robot.base_from_link0;
  for (Eigen::Index j = 0; j < joints.size(); ++j)
    t = t * DHLinkTransform(robot.joints[j], joints[j], robot.convention);
  t = t * robot.flange_from_hand;
  t.row(3) << 0, 0, 0, 1;
  return t;
}

RowMatX16 ForwardKinematics(
    const DHRobot& robot,
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>&
        joints) {
  const Eigen::Index n = static_cast<Eigen::Index>(robot.joints.size());
  if (n == 0) throw std::invalid_argument("the robot has no joints");
  if (joints.cols() != n) {
    std::ostringstream msg;
    msg << "joint readings have " << joints.cols() << " columns but the robot has " << n
        << " joints";
    throw std::invalid_argument(msg.str());
  }
  RowMatX16 poses(joints.rows(), 16);
  for (Eigen::Index i = 0; i < joints.rows(); ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      if (!std::isfinite(joints(i, j))) {
        std::ostringstream msg;
        msg << "joint reading " << i << " is not finite (joint " << j + 1 << ")";
        throw std::invalid_argument(msg.str());
      }
    }
    const Eigen::Matrix4d t = BaseFromHand(robot, joints.row(i).transpose());
    for (int rr = 0; rr < 4; ++rr)
      for (int cc = 0; cc < 4; ++cc) poses(i, rr * 4 + cc) = t(rr, cc);
  }
  return poses;
}

}  // namespace hmlvs::geometry
