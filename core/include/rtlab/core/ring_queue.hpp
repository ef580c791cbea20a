#pragma once
// A FIFO queue in one growable ring buffer: push_back, front, pop_front,
// size, clear. Unlike std::deque it allocates only when it grows past its
// largest size so far, never while it moves through memory (the timing
// model's queues push and pop millions of times a frame).
#include <cstddef>
#include <utility>
#include <vector>

namespace rtlab {

template <class T>
class RingQueue {
public:
    bool empty() const { return size_ == 0; }
    std::size_t size() const { return size_; }
    const T& front() const { return items_[head_]; }
    T& front() { return items_[head_]; }
    void push_back(const T& value) {
        if (size_ == items_.size()) grow();
        std::size_t tail = head_ + size_;
        if (tail >= items_.size()) tail -= items_.size();
        items_[tail] = value;
        ++size_;
    }
    void pop_front() {
        if (++head_ == items_.size()) head_ = 0;
        --size_;
    }
    void clear() { head_ = size_ = 0; }

private:
    void grow() {
        std::vector<T> bigger(items_.empty() ? 16 : items_.size() * 2);
        for (std::size_t i = 0; i < size_; ++i) {
            std::size_t at = head_ + i;
            if (at >= items_.size()) at -= items_.size();
            bigger[i] = std::move(items_[at]);
        }
        items_ = std::move(bigger);
        head_ = 0;
    }
    std::vector<T> items_;
    std::size_t head_ = 0, size_ = 0;
};

}  // namespace rtlab
