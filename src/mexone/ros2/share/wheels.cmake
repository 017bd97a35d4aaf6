# Included by every package here (mexone.ros2.interfaces builds them against PyPI's ROS 2 wheels).
# The wheels' exported rosidl Python targets name the include folder of the machine that built
# them: point each dependency's at this machine's Python headers.
function(mexone_use_local_python_headers)
  foreach(dep ${ARGN})
    if(TARGET ${dep}::${dep}__rosidl_generator_py)
      set_target_properties(${dep}::${dep}__rosidl_generator_py PROPERTIES
        INTERFACE_INCLUDE_DIRECTORIES "${Python3_INCLUDE_DIRS}")
    endif()
  endforeach()
endfunction()
