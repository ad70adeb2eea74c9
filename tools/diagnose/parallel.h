// Independent pieces of diagnose's linear algebra on the machine's cores (no plugin is called
// from these: the force-plugin ABI does not promise that one may run on two threads).
#pragma once

#include <algorithm>
#include <atomic>
#include <exception>
#include <system_error>
#include <thread>
#include <vector>

namespace spml::diagnose_detail {

// f(0) ... f(n-1), on up to four threads. Each call must write only its own results, so the
// numbers are the same on any number of threads; the first exception, in index order, is
// rethrown after every call has ended.
template <typename F>
void parallel_for(size_t n, const F& f) {
  std::vector<std::exception_ptr> failed(n);
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next++) < n;) try {
        f(i);
      } catch (...) {
        failed[i] = std::current_exception();
      }
  };
  const size_t threads = std::min<size_t>(n, std::clamp(std::thread::hardware_concurrency(), 1u, 4u));
  std::vector<std::thread> pool;
  try {
    for (size_t t = 1; t < threads; ++t) pool.emplace_back(work);
  } catch (const std::system_error&) {
    // no more threads to be had: the ones started and this one do the rest
  }
  work();
  for (auto& t : pool) t.join();
  for (const auto& e : failed)
    if (e) std::rethrow_exception(e);
}

}  // namespace spml::diagnose_detail
