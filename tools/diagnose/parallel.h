// Independent pieces of diagnose's work on the machine's cores: its linear algebra, and the
// simulations of a force plugin whose library flags its instances independent
// (SPML_FORCE_INDEPENDENT, force-plugin ABI revision 1; each thread walks its own instance).
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
// A call from inside another's f runs on the calling thread alone (the outer one already fills
// the cores); `serial` asks for that too (a plugin that may not run on two threads).
inline thread_local bool in_parallel_for = false;
// The most threads a call uses (0: the machine's cores, at most four); set for a diagnosis by
// ThreadCap (DiagnoseOptions::threads, --threads).
inline std::atomic<unsigned> max_threads{0};
struct ThreadCap {
  explicit ThreadCap(unsigned n) : before(max_threads.exchange(n)) {}
  ~ThreadCap() { max_threads = before; }
  ThreadCap(const ThreadCap&) = delete;
  ThreadCap& operator=(const ThreadCap&) = delete;
  unsigned before;
};

template <typename F>
void parallel_for(size_t n, const F& f, bool serial = false) {
  std::vector<std::exception_ptr> failed(n);
  std::atomic<size_t> next{0};
  const unsigned cap = max_threads > 0 ? max_threads.load() : std::clamp(std::thread::hardware_concurrency(), 1u, 4u);
  const size_t threads = serial || in_parallel_for ? 1 : std::min<size_t>(n, cap);
  auto work = [&] {
    const bool outer = in_parallel_for;
    in_parallel_for = outer || threads > 1;
    for (size_t i; (i = next++) < n;) try {
        f(i);
      } catch (...) {
        failed[i] = std::current_exception();
      }
    in_parallel_for = outer;
  };
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
