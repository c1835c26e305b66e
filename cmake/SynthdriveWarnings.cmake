# Warning and sanitizer flags as interface targets, so every module opts in the same way.
add_library(synthdrive_warnings INTERFACE)
target_compile_options(synthdrive_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wno-unused-parameter>)
if(SYNTHDRIVE_WERROR)
  target_compile_options(synthdrive_warnings INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
endif()

add_library(synthdrive_sanitizers INTERFACE)
if(SYNTHDRIVE_ASAN)
  target_compile_options(synthdrive_sanitizers INTERFACE
    $<$<COMPILE_LANGUAGE:CXX>:-fsanitize=address,undefined -fno-omit-frame-pointer>)
  target_link_options(synthdrive_sanitizers INTERFACE -fsanitize=address,undefined)
endif()
