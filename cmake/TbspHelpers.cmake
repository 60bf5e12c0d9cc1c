# tbsp_set_warnings(target): our code builds warning-free with -Wall -Wextra.
function(tbsp_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
endfunction()
