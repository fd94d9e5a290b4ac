# OpenCV core and imgproc (images are read and written with libpng, see include/lidar2d/io/image.hpp).
# Debian ships OpenCV's CMake package only in the libopencv-dev meta-package (about 150 packages,
# all modules); we depend on the two small -dev packages and locate their headers and libraries
# here when the full CMake package is absent.
find_package(OpenCV QUIET COMPONENTS core imgproc)
add_library(lidar2d_opencv INTERFACE)
if(OpenCV_FOUND)
  target_link_libraries(lidar2d_opencv INTERFACE ${OpenCV_LIBS})
  target_include_directories(lidar2d_opencv SYSTEM INTERFACE ${OpenCV_INCLUDE_DIRS})
else()
  find_path(LIDAR2D_OPENCV_INCLUDE opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
  foreach(_m core imgproc)
    find_library(LIDAR2D_OPENCV_${_m} NAMES opencv_${_m} REQUIRED)
    target_link_libraries(lidar2d_opencv INTERFACE ${LIDAR2D_OPENCV_${_m}})
  endforeach()
  target_include_directories(lidar2d_opencv SYSTEM INTERFACE ${LIDAR2D_OPENCV_INCLUDE})
endif()
