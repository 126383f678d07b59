# ctest bus_bench_smoke: runs `bus_bench --smoke --json JSON` and checks the JSON: an array of rows,
# each with the required keys and sane values, and rows of every transport (iceoryx only if built
# with it and its RouDi could start).
#
# Delivery is checked by what holds under any load, not by `lost == 0`: a subscriber descheduled
# by other load for a queue depth of periods (4 x 4 ms here) is a slow subscriber then, and its
# queue drops by the documented keep-last policy. So in every row nothing taken is out of order or duplicated (`reordered`),
# corrupt (`checksum_errors`) or stale, and in every 1->1 row and the probeless slow_subscriber row
# `unexplained == 0`: each miss is counted by the transport itself (probeless: the subscriber's
# `dropped`; UDS: the publisher's drop-newest) with the count equal to the misses, and for
# drop-oldest queues it happened only after the subscriber fell a queue depth behind (a taken
# message waited that long), never in a flow-controlled throughput phase (bus_bench's Accumulate).
# For probeless the bus's own count must equal the misses (no message neither delivered nor
# counted as dropped) and the publisher never failed a loan.
cmake_minimum_required(VERSION 3.25)

if(NOT BUS_BENCH OR NOT JSON)
  message(FATAL_ERROR "usage: cmake -DBUS_BENCH=<exe> -DJSON=<file> -P check_smoke.cmake")
endif()

file(REMOVE "${JSON}")
execute_process(COMMAND "${BUS_BENCH}" --smoke --json "${JSON}"
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 55)
message("${out}${err}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "bus_bench --smoke failed (exit ${rc})")
endif()

file(READ "${JSON}" text)
string(JSON n ERROR_VARIABLE json_error LENGTH "${text}")
if(json_error)
  message(FATAL_ERROR "${JSON} is not a JSON array: ${json_error}")
endif()
if(n EQUAL 0)
  message(FATAL_ERROR "${JSON} has no rows")
endif()

set(required transport size mode subscribers p50_us p90_us p99_us max_us msgs_per_s lost
    counted_drops unexplained reordered stale checksum_errors loan_failures)
set(seen_transports "")
math(EXPR last "${n} - 1")
foreach(i RANGE ${last})
  foreach(key IN LISTS required)
    string(JSON value ERROR_VARIABLE key_error GET "${text}" ${i} ${key})
    if(key_error)
      message(FATAL_ERROR "row ${i} lacks key '${key}': ${key_error}")
    endif()
    set(${key} "${value}")
  endforeach()
  if(NOT transport MATCHES "^(probeless|uds|iceoryx)$")
    message(FATAL_ERROR "row ${i}: transport '${transport}'")
  endif()
  if(NOT mode MATCHES "^(blocking|busy)$")
    message(FATAL_ERROR "row ${i}: mode '${mode}'")
  endif()
  if(NOT size GREATER 0 OR NOT subscribers GREATER 0)
    message(FATAL_ERROR "row ${i}: size ${size}, subscribers ${subscribers}")
  endif()
  if(NOT p50_us GREATER 0 OR p90_us LESS p50_us OR p99_us LESS p90_us OR max_us LESS p99_us)
    message(FATAL_ERROR "row ${i} (${transport} ${size}): percentiles not ordered: "
                        "${p50_us} ${p90_us} ${p99_us} ${max_us}")
  endif()
  if(NOT msgs_per_s GREATER 0)
    message(FATAL_ERROR "row ${i} (${transport} ${size}): msgs_per_s ${msgs_per_s}")
  endif()
  if(NOT reordered EQUAL 0 OR NOT stale EQUAL 0 OR NOT checksum_errors EQUAL 0)
    message(FATAL_ERROR "row ${i} (${transport} ${size} B ${mode}): ${reordered} taken out of "
                        "order or twice, ${stale} stale, ${checksum_errors} corrupt")
  endif()
  if(subscribers EQUAL 1)
    if(NOT unexplained EQUAL 0)
      message(FATAL_ERROR "row ${i} (${transport} ${size} B ${mode}): lost ${lost} in a 1->1 row, "
                          "${unexplained} of them neither counted by the transport nor its "
                          "queue policy (transport counted ${counted_drops})")
    endif()
    if(transport STREQUAL "probeless" AND
       (NOT counted_drops EQUAL lost OR NOT loan_failures EQUAL 0))
      message(FATAL_ERROR "row ${i} (probeless ${size} B ${mode}): lost ${lost} in a 1->1 row, "
                          "the bus counted ${counted_drops} dropped (loan failures "
                          "${loan_failures}): a message neither delivered nor counted")
    endif()
    if(NOT lost EQUAL 0)
      message(STATUS "row ${i} (${transport} ${size} B ${mode}): lost ${lost}, all accounted "
                     "for (transport counted ${counted_drops}; a subscriber descheduled by load)")
    endif()
  endif()
  string(JSON scenario ERROR_VARIABLE scenario_error GET "${text}" ${i} scenario)
  if(NOT scenario_error AND scenario STREQUAL "slow_subscriber" AND transport STREQUAL "probeless")
    string(JSON fast_drops ERROR_VARIABLE drops_error GET "${text}" ${i} fast_transport_drops)
    if(drops_error)
      message(FATAL_ERROR "row ${i} (probeless slow_subscriber) lacks fast_transport_drops")
    endif()
    string(JSON loan_failures GET "${text}" ${i} loan_failures)
    if(NOT lost EQUAL fast_drops OR NOT loan_failures EQUAL 0 OR NOT unexplained EQUAL 0)
      message(FATAL_ERROR "row ${i} (probeless slow_subscriber): fast subscribers lost ${lost}, "
                          "of which their own full queues dropped ${fast_drops} (loan failures "
                          "${loan_failures}, unexplained ${unexplained}): the bus lost a fast "
                          "subscriber's message")
    endif()
    set(seen_slow ON)
  endif()
  list(APPEND seen_transports ${transport})
endforeach()
if(NOT seen_slow)
  message(FATAL_ERROR "no probeless slow_subscriber row")
endif()

foreach(t probeless uds)
  if(NOT t IN_LIST seen_transports)
    message(FATAL_ERROR "no ${t} rows")
  endif()
endforeach()
if(EXPECT_ICEORYX AND NOT "iceoryx" IN_LIST seen_transports)
  if(out MATCHES "iox-roudi cannot start")
    message(WARNING "no iceoryx rows: RouDi could not start (see above)")
  else()
    message(FATAL_ERROR "no iceoryx rows although bus_bench was built with iceoryx")
  endif()
endif()
message(STATUS "bus_bench smoke JSON OK: ${n} rows (${seen_transports})")
