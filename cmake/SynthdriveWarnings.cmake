# Warning and sanitizer flags as interface targets, so every module opts in the same way.
add_library(synthdrive_warnings INTERFACE)
target_compile_options(synthdrive_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wno-unused-parameter>)
if(SYNTHDRIVE_WERROR)
  target_compile_options(synthdrive_warnings INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
endif()

add_library(synthdrive_sanitizers INTERFACE)
# A UBSan report stops the program (no recovery), so any report fails the test or the fuzz run.
if(SYNTHDRIVE_ASAN OR SYNTHDRIVE_FUZZ)
  target_compile_options(synthdrive_sanitizers INTERFACE
    $<$<COMPILE_LANGUAGE:CXX>:-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer>)
  target_link_options(synthdrive_sanitizers INTERFACE -fsanitize=address,undefined -fno-sanitize-recover=undefined)
endif()
# Coverage feedback for libFuzzer in every module the targets link; the targets themselves link -fsanitize=fuzzer.
if(SYNTHDRIVE_FUZZ)
  target_compile_options(synthdrive_sanitizers INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-fsanitize=fuzzer-no-link>)
endif()
