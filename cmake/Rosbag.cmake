# Debian 12 packages ROS1's rosbag_storage (librosbag-storage-dev) but its pkg-config file fails
# on pluginlib (Debian mixes ROS1 and ROS2 headers), so we locate the libraries and the nested
# include folders by hand. Only src/io/rosbag1_reader.cpp includes ROS headers, and only the
# container ones (rosbag/bag.h, view.h, ros/serialization.h), which compile as C++20. The generated
# message headers (sensor_msgs/LaserScan.h, ...) do not (they use std::allocator<void>::rebind,
# removed in C++20), so messages are decoded by src/io/internal/ros_messages.cpp instead; no
# per-file -std=c++17 is needed. roslz4 is listed for bags with lz4 chunks.
set(_ros_libs rosbag_storage roscpp_serialization rostime cpp_common console_bridge class_loader
              ament_index_cpp roslz4)
set(_ros_found_libs)
foreach(_l IN LISTS _ros_libs)
  find_library(LIDAR2D_ROS_${_l} NAMES ${_l})
  if(NOT LIDAR2D_ROS_${_l})
    message(FATAL_ERROR "lib${_l} not found: install librosbag-storage-dev (tools/install-deps.sh)")
  endif()
  list(APPEND _ros_found_libs ${LIDAR2D_ROS_${_l}})
endforeach()
find_path(LIDAR2D_ROSBAG_INCLUDE rosbag/bag.h REQUIRED)
add_library(lidar2d_rosbag_deps INTERFACE)
foreach(_d ament_index_cpp class_loader pluginlib rcpputils rcutils)
  if(IS_DIRECTORY /usr/include/${_d}/${_d})
    target_include_directories(lidar2d_rosbag_deps SYSTEM INTERFACE /usr/include/${_d})
  endif()
endforeach()
target_link_libraries(lidar2d_rosbag_deps INTERFACE ${_ros_found_libs})
