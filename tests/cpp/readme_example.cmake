# The README's C++ example as written: the ```cpp block between its markers
# <!-- cpp:readme-example ... --> and <!-- /cpp:readme-example -->, copied to OUT (rewritten only
# when it changed, so an untouched README rebuilds nothing). README.md edits re-run the configure.
function(pinsettle_readme_example README OUT)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${README}")
  file(READ "${README}" text)
  string(FIND "${text}" "<!-- cpp:readme-example" begin)
  string(FIND "${text}" "<!-- /cpp:readme-example -->" end)
  if(begin EQUAL -1 OR end EQUAL -1 OR end LESS begin)
    message(FATAL_ERROR "${README}: no <!-- cpp:readme-example --> ... "
                        "<!-- /cpp:readme-example --> markers around the C++ example")
  endif()
  math(EXPR length "${end} - ${begin}")
  string(SUBSTRING "${text}" ${begin} ${length} block)
  # The marker's line, then the fenced block and nothing else.
  if(NOT block MATCHES "^<!--[^\n]*-->\n```cpp\n(.*)```[ \n]*$")
    message(FATAL_ERROR "${README}: the text between the cpp:readme-example markers is not one "
                        "```cpp block")
  endif()
  file(WRITE "${OUT}.in" "${CMAKE_MATCH_1}")
  configure_file("${OUT}.in" "${OUT}" COPYONLY)
endfunction()
